"""systems.common: the shared parameter checks, the cross product and the smoothstep."""

import numpy as np
import pytest

from systems.common.checks import per_joint
from systems.common.smoothing import smoothstep5
from systems.common.spatial import cross, skew


def test_per_joint_scalars_sequences_and_mappings():
    np.testing.assert_array_equal(per_joint(2.0, 3, "kp"), [2.0, 2.0, 2.0])
    np.testing.assert_array_equal(per_joint([1, 2, 3], 3, "kp"), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(per_joint({"b": 2.0, "a": 1.0}, ("a", "b"), "kd"), [1.0, 2.0])
    source = np.array([1.0, 2.0])
    out = per_joint(source, 2, "kp")
    out[0] = 5.0
    assert source[0] == 1.0  # a copy
    assert per_joint(np.inf, 2, "max_rate", allow_inf=True).tolist() == [np.inf, np.inf]


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(value=[1.0, 2.0], joints=3), r"S: kp must be a scalar or have shape \(3,\), got shape \(2,\)"),
        (dict(value=np.ones((3, 1)), joints=3), r"S: kp must be a scalar or have shape \(3,\)"),
        (dict(value="x", joints=3), "S: kp must be a number or an array of 3 numbers"),
        (dict(value=[1.0, np.nan, 1.0], joints=3), r"S: kp has non-finite entries at indices \[1\]"),
        (dict(value=[1.0, np.inf, 1.0], joints=3), r"S: kp has non-finite entries at indices \[1\]"),
        (dict(value={"a": 1.0}, joints=("a", "b")), r"S: kp has no value for \['b'\]"),
        (dict(value={"a": 1.0}, joints=1), "S: kp must be a scalar or 1 values, not a mapping"),
        (
            dict(value=[1.0, -1.0], joints=2, sign="non-negative"),
            r"S: kp must be non-negative; negative at joint indices \[1\]",
        ),
        (
            dict(value=[1.0, 0.0], joints=2, sign="positive"),
            r"S: kp must be positive; not positive at joint indices \[1\]",
        ),
    ],
)
def test_per_joint_refuses_bad_values_naming_system_and_parameter(kwargs, match):
    with pytest.raises(ValueError, match=match):
        per_joint(kwargs.pop("value"), kwargs.pop("joints"), "kp", who="S", **kwargs)


def test_cross_matches_numpy_bit_for_bit_and_broadcasts():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    for x, y in zip(a, b):
        assert cross(x, y).tolist() == np.cross(x, y).tolist()
        np.testing.assert_allclose(skew(x) @ y, cross(x, y), rtol=1e-14, atol=1e-15)
    assert cross(a, b).tolist() == np.cross(a, b).tolist()
    assert cross(a, b[0]).shape == (5, 3)
    with pytest.raises(ValueError, match="3-vectors"):
        cross(np.ones(2), np.ones(2))


def test_smoothstep5_clips_and_has_the_same_bits_for_floats_and_arrays():
    s = np.linspace(-0.5, 1.5, 41)
    values = smoothstep5(s)
    assert values[0] == 0.0 and values[-1] == 1.0
    assert smoothstep5(0.5) == 0.5
    assert all(smoothstep5(float(x)) == v for x, v in zip(s, values))
    assert type(smoothstep5(0.3)) is float
    x = np.clip(s, 0.0, 1.0)
    np.testing.assert_allclose(values, 10 * x**3 - 15 * x**4 + 6 * x**5, rtol=0, atol=1e-14)
