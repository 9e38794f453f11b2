"""Reproducible sensor noise: zero-mean Gaussian white noise, sample-and-hold.

``SampledNoise(dimension, std, period, seed).value(t)`` is a pure function of
(seed, k) with the sample index k = floor(t / period + 1e-9): the noise is held constant
over each period [k T, (k + 1) T) and changes at every multiple of the period. Drake may
evaluate an output port several times per step (and the simulator may re-evaluate a
time after a rollback), so the value must not depend on how often or in which order it
is asked for; it is therefore not drawn from a running generator but generated in blocks
of :data:`BLOCK_SIZE` samples, block b coming from ``np.random.default_rng([seed, b])``.
The most recent blocks are cached, so a call costs a dictionary lookup and a copy.

Two noises with different seeds are independent (different entropy for NumPy's
``SeedSequence``); the realisation does not depend on ``std`` other than by scaling, so
changing one entry's standard deviation leaves the others' samples unchanged.

``NoisyVector`` is a LeafSystem adding such noise to a vector signal; ``RandomWalkBias``
adds a random-walk bias (and optionally the white noise too, in one system).
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from systems.common.checks import check_finite_input, per_joint

#: Samples generated per random-generator call (one block per (seed, block index)).
BLOCK_SIZE = 1024
#: Number of blocks kept in each noise's cache.
CACHED_BLOCKS = 4
#: Tolerance added to t / period before flooring, so that t = k T (in floating point)
#: falls in sample k.
INDEX_TOLERANCE = 1e-9


def as_std_vector(std, dimension: int, name: str = "std") -> np.ndarray:
    """Returns ``std`` (scalar or ``dimension`` entries) as a float array of ``dimension``.

    Raises:
        ValueError: wrong shape, NaN/inf or negative entries; the message names ``name``.
    """
    return per_joint(std, dimension, name, sign="non-negative", entry="entry")


def check_period(period, name: str = "period") -> float:
    """Returns ``period`` as a float; raises ValueError unless it is finite and > 0."""
    try:
        value = float(period)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} must be a positive number of seconds, got {period!r}") from err
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a positive number of seconds, got {period!r}")
    return value


def check_seed(seed, name: str = "seed") -> int:
    """Returns ``seed`` as an int; raises ValueError unless it is a non-negative integer."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"{name} must be a non-negative integer, got {seed!r}")
    if seed < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {seed}")
    return int(seed)


class SampledNoise:
    """Zero-mean Gaussian white noise held over periods of ``period`` seconds.

    value(t) = std ⊙ n_k with n_k ~ N(0, I) (``dimension`` entries) a deterministic
    function of (seed, k), k = floor(t / period + 1e-9).

    Args:
        dimension: number of entries (>= 0).
        std: standard deviation per entry, scalar or ``dimension`` entries, in the units
            of the signal it is added to (SI); 0 entries give exactly 0.
        period: sample-and-hold period T, s (> 0).
        seed: non-negative integer; different seeds give independent noises.

    Raises:
        ValueError: bad dimension, std, period or seed (the message names it).
    """

    def __init__(self, dimension: int, std, period: float, seed: int):
        if isinstance(dimension, (bool, np.bool_)) or not isinstance(dimension, (int, np.integer)) or dimension < 0:
            raise ValueError(f"dimension must be a non-negative integer, got {dimension!r}")
        self._dimension = int(dimension)
        self._std = as_std_vector(std, self._dimension, "std")
        self._period = check_period(period)
        self._seed = check_seed(seed)
        self._zero = not np.any(self._std > 0.0)
        self._blocks: OrderedDict[int, np.ndarray] = OrderedDict()

    @property
    def dimension(self) -> int:
        return self._dimension

    @property
    def std(self) -> np.ndarray:
        """The standard deviation per entry (a copy)."""
        return self._std.copy()

    @property
    def period(self) -> float:
        return self._period

    @property
    def seed(self) -> int:
        return self._seed

    @property
    def is_zero(self) -> bool:
        """True when every std is 0 (value() returns zeros without drawing)."""
        return self._zero

    def sample_index(self, t: float) -> int:
        """k = floor(t / period + 1e-9), the index of the sample held at time t (s)."""
        if not t >= 0.0:  # also catches NaN
            raise ValueError(f"SampledNoise: time must be >= 0, got {t!r}")
        return int(math.floor(t / self._period + INDEX_TOLERANCE))

    def sample(self, k: int) -> np.ndarray:
        """The k-th sample (k >= 0), std-scaled: a new array of ``dimension`` entries."""
        if self._zero:
            return np.zeros(self._dimension)
        if k < 0:
            raise ValueError(f"SampledNoise: sample index must be >= 0, got {k}")
        block_index, row = divmod(k, BLOCK_SIZE)
        block = self._blocks.get(block_index)
        if block is None:
            rng = np.random.default_rng([self._seed, block_index])
            block = rng.standard_normal((BLOCK_SIZE, self._dimension)) * self._std
            self._blocks[block_index] = block
            while len(self._blocks) > CACHED_BLOCKS:
                self._blocks.popitem(last=False)
        return block[row].copy()

    def value(self, t: float) -> np.ndarray:
        """The noise at time t (s): a new array of ``dimension`` entries."""
        if self._zero:
            return np.zeros(self._dimension)
        return self.sample(self.sample_index(t))


class NoisyVector(LeafSystem):
    """Adds sampled Gaussian noise (see SampledNoise) to a vector signal.

    Inputs:
        clean: the signal, ``size`` entries (any units).

    Outputs:
        noisy: clean(t) + noise(t), same units; direct feedthrough, no delay; the noise is
            held over each ``period``.

    Args:
        size: signal size.
        std: noise standard deviation, scalar or per entry, in the signal's units.
        period: noise sample-and-hold period, s.
        seed: noise seed (non-negative integer).

    Raises:
        ValueError: bad size, std, period or seed; NaN/inf on ``clean`` (at evaluation).
    """

    def __init__(self, size: int, std, period: float = 1e-3, seed: int = 0):
        super().__init__()
        if isinstance(size, (bool, np.bool_)) or not isinstance(size, (int, np.integer)) or size < 1:
            raise ValueError(f"size must be a positive integer, got {size!r}")
        self._noise = SampledNoise(int(size), std, period, seed)
        self._clean = self.DeclareVectorInputPort("clean", int(size))
        self.DeclareVectorOutputPort("noisy", int(size), self._CalcNoisy)

    @property
    def noise(self) -> SampledNoise:
        return self._noise

    def _CalcNoisy(self, context: Context, output: BasicVector) -> None:
        clean = self._clean.Eval(context)
        check_finite_input("NoisyVector", "clean", clean)
        if self._noise.is_zero:
            output.SetFromVector(clean)
        else:
            output.SetFromVector(clean + self._noise.value(context.get_time()))


class RandomWalkBias(LeafSystem):
    """Adds a slowly varying bias, a Gaussian random walk, to a vector signal, and
    optionally white noise.

    The bias b is discrete state, updated every ``period`` T seconds:
    b_{k+1} = b_k + sigma sqrt(T) n_k, n_k ~ N(0, I) a pure function of (seed, k) (see
    ``SampledNoise``), b_0 = ``initial_bias`` (default 0: the bias is calibrated at
    start-up; else the sensor's constant turn-on bias). So the bias at time t = k T is b_0
    plus a walk of standard deviation sigma sqrt(t) per entry (Kalibr's "bias random walk"
    model, sigma in signal units per sqrt(s), i.e. per s per sqrt(Hz)).

    With ``white_noise_std`` the system also adds the white noise w(t) of a
    ``NoisyVector(size, white_noise_std, period, white_noise_seed)``, before the bias: the
    output is then (clean + w) + b, the same numbers as that NoisyVector followed by this
    system, in one system (an IMU axis's noise and bias, evaluated once per step).

    Inputs:
        clean: the signal, ``size`` entries (any units).

    Outputs:
        biased: clean(t) (+ w(t)) + b(t), same units; direct feedthrough from ``clean``.

    Args:
        size: signal size (>= 1).
        random_walk: sigma per entry, scalar or ``size`` entries (>= 0), signal units / sqrt(s).
        period: update period T, s (> 0); also the white noise's sample-and-hold period.
        seed: non-negative integer.
        white_noise_std: the white noise's standard deviation, scalar or ``size`` entries
            (>= 0), signal units; None (default): none.
        white_noise_seed: its seed (non-negative integer; needed with ``white_noise_std``).
        initial_bias: b_0, scalar or ``size`` finite entries, signal units (default 0).

    Raises:
        ValueError: bad size, random_walk, period, seed, white noise or initial bias (the
            message names it),
            NaN/inf on ``clean`` (at evaluation).
    """

    def __init__(
        self,
        size: int,
        random_walk,
        period: float = 1e-3,
        seed: int = 0,
        *,
        white_noise_std=None,
        white_noise_seed: int | None = None,
        initial_bias=0.0,
    ):
        super().__init__()
        if isinstance(size, (bool, np.bool_)) or not isinstance(size, (int, np.integer)) or size < 1:
            raise ValueError(f"size must be a positive integer, got {size!r}")
        period = check_period(period)
        sigma = as_std_vector(random_walk, int(size), "random_walk")
        self._increments = SampledNoise(int(size), sigma * math.sqrt(period), period, seed)
        if (white_noise_std is None) != (white_noise_seed is None):
            raise ValueError("white_noise_std and white_noise_seed go together (one was given without the other)")
        white_std = 0.0 if white_noise_std is None else as_std_vector(white_noise_std, int(size), "white_noise_std")
        white_seed = 0 if white_noise_seed is None else check_seed(white_noise_seed, "white_noise_seed")
        self._white = SampledNoise(int(size), white_std, period, white_seed)
        self._period = period
        self._clean = self.DeclareVectorInputPort("clean", int(size))
        try:
            initial = np.asarray(initial_bias, dtype=float)
        except (TypeError, ValueError):
            initial = np.full(1, np.nan)
        if initial.ndim == 0:
            initial = np.full(int(size), float(initial))
        if initial.shape != (int(size),) or not np.isfinite(initial).all():
            raise ValueError(
                f"initial_bias must be a finite scalar or {int(size)} finite entries, got {initial_bias!r}"
            )
        self._bias = self.DeclareDiscreteState(initial)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._Update)
        self.DeclareVectorOutputPort("biased", int(size), self._CalcBiased)

    @property
    def increments(self) -> SampledNoise:
        """The increments' noise stream (std sigma sqrt(T) per entry)."""
        return self._increments

    @property
    def noise(self) -> SampledNoise:
        """The white noise added before the bias (all stds 0 without ``white_noise_std``),
        as ``NoisyVector.noise``."""
        return self._white

    def get_bias(self, context: Context) -> np.ndarray:
        """The current bias b, signal units (a copy)."""
        return context.get_discrete_state(self._bias).CopyToVector()

    def _Update(self, context: Context, state) -> None:
        k = int(round(context.get_time() / self._period))
        bias = context.get_discrete_state(self._bias).get_value()
        state.get_mutable_vector(self._bias).SetFromVector(bias + self._increments.sample(k))

    def _CalcBiased(self, context: Context, output: BasicVector) -> None:
        clean = self._clean.Eval(context)
        check_finite_input("RandomWalkBias", "clean", clean)
        if not self._white.is_zero:
            clean = clean + self._white.value(context.get_time())
        output.SetFromVector(clean + context.get_discrete_state(self._bias).get_value())


__all__ = [
    "BLOCK_SIZE",
    "NoisyVector",
    "RandomWalkBias",
    "SampledNoise",
    "as_std_vector",
    "check_finite_input",
    "check_period",
    "check_seed",
]
