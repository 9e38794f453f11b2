"""Push and comply (Sec. IV): scenarios, the closed loop on a short horizon, the app and its
replay in a real browser."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlantConfig

from apps import push_and_comply
from apps.push_and_comply import run_once
from diagrams.residuals.push_and_comply import PushAndComplyScenario, build_push_and_comply_diagram, load_scenario
from diagrams.scenarios import scenario_as_dict
from diagrams.station.config import StationConfig
from systems.simulation.visualization import read_static_html
from tests.headless_chromium import requires_chromium, run_chromium

SCENARIOS = Path(push_and_comply.__file__).parent / "scenarios"

# A compressed version of the paper's scenario: the same push, 3.5 s instead of 15 s.
# Its push rises 3x faster than the default's, so the residual gain is the contact detector's: the
# default's 5/s would lag its 1.2 s rise by 0.2 s (27 % RMS error against the true effort).
SHORT = dict(duration=3.5, tare_duration=0.4, push_start=0.5, push_peak_time=1.7, push_end=3.0, residual_gain=35.0)


def test_scenario_files_load_into_the_dataclass(tmp_path):
    # Drake's config types have no ==: compare every field through YAML.
    default = scenario_as_dict(PushAndComplyScenario())
    assert scenario_as_dict(load_scenario(None)) == default
    assert scenario_as_dict(load_scenario(SCENARIOS / "push_and_comply_default.yaml")) == default
    overridden = load_scenario(
        SCENARIOS / "paper_5N.yaml", text="station: {seed: 7, plant_config: {discrete_contact_approximation: lagged}}"
    )
    assert (overridden.push_peak_force, overridden.station.seed) == (5.0, 7)
    assert (
        overridden.station.plant_config.discrete_contact_approximation == "lagged"
        and overridden.station.plant_config.time_step == 1e-3
    )
    paper = load_scenario(SCENARIOS / "paper_5N.yaml")
    assert paper.push_peak_force == 5.0 and paper.duration == 15.0  # other keys keep the defaults
    with pytest.raises(ValueError, match="does not exist"):
        load_scenario(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("push_peak_force: [1, 2]\n")
    with pytest.raises(ValueError, match="could not read the scenario file"):
        load_scenario(bad)
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text("push_strength: 3\n")
    with pytest.raises(ValueError, match="push_strength"):
        load_scenario(unknown)
    with pytest.raises(ValueError, match="push_start < push_peak_time"):
        build_push_and_comply_diagram(PushAndComplyScenario(push_peak_time=20.0), "internal")
    with pytest.raises(ValueError, match="the tare must not average the push"):
        build_push_and_comply_diagram(PushAndComplyScenario(tare_duration=5.5), "internal")
    with pytest.raises(ValueError, match="unknown residual"):
        build_push_and_comply_diagram(PushAndComplyScenario(), "magic")
    with pytest.raises(ValueError, match="unknown contact approximation 'ode'"):
        build_push_and_comply_diagram(
            PushAndComplyScenario(
                station=StationConfig.realistic(
                    plant_config=MultibodyPlantConfig(
                        time_step=1e-3, contact_model="point", discrete_contact_approximation="ode"
                    )
                )
            ),
            "internal",
        )


@pytest.fixture(scope="module")
def short_runs():
    scenario = PushAndComplyScenario(station=StationConfig(), **SHORT, push_peak_force=30.0)
    return scenario, {kind: run_once(scenario, kind, None, progress=False) for kind in ("internal", "classical")}


def _assert_knees_flex_with_internal_only(internal: dict, classical: dict) -> None:
    """The paper's Figs. 5-6 on the two runs' metrics: driven by the internal residual the
    knees flex; driven by the classical one they do not, and the chest takes the motion;
    upright and without slip in both."""
    assert internal["knee_pitch_flexion_deg"] > 1.0
    assert abs(classical["knee_pitch_flexion_deg"]) < 0.2 * internal["knee_pitch_flexion_deg"]
    moved = classical["max_joint_displacement_deg"]
    assert moved["CHEST_P"] > 1.0 and max(moved, key=moved.get) == "CHEST_P"
    for metrics in (internal, classical):
        assert metrics["upright"] and metrics["max_foot_slip_m"] < 0.005


def test_internal_residual_bends_the_legs_and_classical_does_not(short_runs):
    """The paper's Figs. 5-6 on a short horizon: driven by the internal residual the knees
    flex; driven by the classical one they do not, and the chest takes the motion."""
    scenario, runs = short_runs
    internal = runs["internal"]["metrics"]
    classical = runs["classical"]["metrics"]
    _assert_knees_flex_with_internal_only(internal, classical)


def test_the_scenario_uses_sap_and_deprecated_tamsi_is_refused():
    """Drake deprecated TAMSI (removal on or after 2026-09-01): the scenario runs on SAP and
    asking for TAMSI gets a message that says why, not a Drake deprecation warning."""
    assert PushAndComplyScenario().station.plant_config.discrete_contact_approximation == "sap"
    with pytest.raises(ValueError, match="deprecated the TAMSI solver"):
        build_push_and_comply_diagram(
            PushAndComplyScenario(
                station=StationConfig.realistic(
                    plant_config=MultibodyPlantConfig(
                        time_step=1e-3, contact_model="point", discrete_contact_approximation="tamsi"
                    )
                )
            ),
            "internal",
        )


@pytest.mark.parametrize(
    "robot",
    ["models/robots/hrp4_like_no_ft.yaml", pytest.param("models/robots/hrp4_like_fsr.yaml", marks=pytest.mark.slow)],
)
def test_without_foot_ft_sensors_the_legs_comply_with_the_push_not_the_weight(robot):
    """A robot without foot F/T sensors (or with FSRs only): the residuals carry the soles'
    changing wrenches, which ``SoleWrenchCompensation`` estimates and removes (without it the
    ideal world's robot collapsed to 54 deg knees in both runs, complying with its own
    weight). The F/T robot's assertions hold: the knees flex with the internal residual and
    not with the classical one, the chest takes the motion, upright, no slip."""
    scenario = PushAndComplyScenario(station=StationConfig(model=robot), **SHORT, push_peak_force=30.0)
    diagram, handles = build_push_and_comply_diagram(scenario, "internal")
    assert diagram.HasSubsystemNamed("sole_wrench_compensation")
    internal = run_once(scenario, "internal", None, progress=False)["metrics"]
    classical = run_once(scenario, "classical", None, progress=False)["metrics"]
    _assert_knees_flex_with_internal_only(internal, classical)


def test_residual_follows_the_true_effort_in_the_loop(short_runs):
    _, runs = short_runs
    s = runs["internal"]["signals"]
    window = s["t"] > 0.7
    error = np.linalg.norm(s["residual"][:, window] - s["tau_c_real"][:, window])
    assert error < 0.2 * np.linalg.norm(s["tau_c_real"][:, window])


@pytest.mark.slow
def test_the_tare_removes_a_torque_sensor_offset_before_the_push():
    """An ideal world but for the torque sensors' offsets (1 % of the rated torques): the raw
    residual carries them without any contact. Without the tare the admittance integrates
    them before anyone pushes; with it the robot stands still until the push, and the
    residual the admittance gets follows the push's true joint effort (the simulator's)."""
    from systems.simulation.imperfections import Imperfections, TorqueSensorImperfections

    timing = dict(
        duration=2.0, push_start=1.0, push_peak_time=1.5, push_end=2.0, push_peak_force=30.0, residual_gain=35.0
    )
    runs = {}
    for tare in (0.0, 0.5):
        scenario = PushAndComplyScenario(station=StationConfig(), **timing, tare_duration=tare)
        scenario.station.imperfections = Imperfections(
            torque_sensor=TorqueSensorImperfections(offset_percent=1.0), seed=3
        )
        runs[tare] = run_once(scenario, "internal", None, progress=False)["signals"]

    def moved_before_push_deg(s):
        q = s["desired_position"]
        return np.degrees(np.abs(q[:, s["t"] <= 1.0] - q[:, [0]]).max())

    assert moved_before_push_deg(runs[0.0]) > 2.0  # the offsets drive the admittance
    assert moved_before_push_deg(runs[0.5]) < 0.05
    s = runs[0.5]
    pushed = s["t"] > 1.2
    true_effort = s["tau_c_real"][:, pushed]
    scale = np.linalg.norm(true_effort)
    assert np.linalg.norm(s["residual"][:, pushed] - true_effort) > 0.5 * scale  # raw: offset-dominated
    assert np.linalg.norm(s["tared_residual"][:, pushed] - true_effort) < 0.2 * scale


@pytest.fixture(scope="module")
def app_output(tmp_path_factory):
    out = tmp_path_factory.mktemp("push_and_comply")
    scenario = out / "short.yaml"
    scenario.write_text(
        "".join(f"{k}: {v}\n" for k, v in {**SHORT, "duration": 1.5, "push_end": 1.4, "push_peak_time": 0.9}.items())
    )
    assert (
        push_and_comply.main(["--headless", "--out", str(out), "--scenario", str(scenario), "--seed", "4", "--ideal"])
        == 0
    )
    return out / "push_and_comply"


def test_app_writes_replays_plots_and_metrics(app_output):
    for name in ("internal.html", "classical.html", "joint_trajectories.png", "residual_vs_true_effort.png"):
        assert (app_output / name).stat().st_size > 20_000, name
    metrics = json.loads((app_output / "metrics.json").read_text())
    for kind in ("internal", "classical"):
        for key in (
            "knee_pitch_flexion_deg",
            "joints_moved_over_1deg",
            "com_height_drop_m",
            "max_foot_slip_m",
            "upright",
            "real_time_factor",
            "max_joint_displacement_deg",
        ):
            assert key in metrics[kind], (kind, key)
        assert isinstance(metrics[kind]["upright"], bool)
    assert metrics["scenario"]["station"]["seed"] == 4


def test_replay_is_self_contained(app_output):
    """No page resource from another host: the replay works offline."""
    html = (app_output / "internal.html").read_text()
    external = re.findall(r"<(?:script|link)[^>]+(?:src|href)\s*=\s*[\"']((?:https?:)?//[^\"']+)", html)
    assert external == []
    # The effort markers and force arrows are animated in the recording (scale/visibility
    # and transforms replay in this Meshcat; colour changes would not).
    scene = read_static_html(html)
    animated = set(scene.tracks)
    assert any("effort" in path for path in animated), sorted(animated)[:5]
    assert any("forces" in path for path in animated), sorted(animated)[:5]
    assert any("visible" in tracks or "scale" in tracks for path, tracks in scene.tracks.items() if "effort" in path)


@requires_chromium
@pytest.mark.slow
def test_replay_renders_the_robot_in_headless_chromium(app_output, tmp_path):
    """Opens the replay in a real browser, offline, and checks that the robot is drawn."""
    from PIL import Image

    screenshot = tmp_path / "replay.png"
    # The virtual-time budget (headless_chromium.FLAGS) is shorter than the recorded animation
    # (1.5 s here).
    run_chromium(
        ["--window-size=1280,800", f"--screenshot={screenshot}"],
        (app_output / "internal.html").resolve().as_uri(),
        tmp_path,
        "replay",
        lambda _: screenshot.is_file(),
    )
    pixels = np.asarray(Image.open(screenshot).convert("RGB")).astype(int)
    # The background and the ground are smooth grey-green gradients; the robot's links are
    # light grey with dark feet, drawn in the middle of the view. Count the pixels of the
    # central region that differ from the border's colours.
    h, w, _ = pixels.shape
    centre = pixels[h // 4 : 3 * h // 4, w // 3 : 2 * w // 3].reshape(-1, 3)
    border = np.concatenate((pixels[:, :20].reshape(-1, 3), pixels[:, -20:].reshape(-1, 3)))
    distance = np.min(np.abs(centre[:, None, :] - border[None, :: max(1, len(border) // 400), :]).sum(axis=2), axis=1)
    assert (distance > 40).mean() > 0.01, "the robot is not visible in the replay"


def test_dead_band_from_the_calibrated_noise_of_each_residual():
    """With a refined model's noise model, each run's dead band is at least
    ``dead_band_sigmas`` standard deviations of its own residual's noise (internal:
    the internal residual's; classical: the classical residual's joint entries), never
    below ``dead_band``; without a classical noise model the classical run keeps
    ``dead_band``; a noise model measured with other gains is refused."""
    from types import SimpleNamespace

    from diagrams.residuals.push_and_comply import admittance_dead_band
    from systems.residuals.offline import ResidualNoiseModel

    scenario = PushAndComplyScenario()
    noise = ResidualNoiseModel(
        internal_gain=scenario.residual_gain,
        external_gain=35.0,
        period=scenario.station.plant_config.time_step,
        covariance_internal=np.diag([1e-6, 0.01, 0.04, 1.0]),
        covariance_external_force=np.eye(3),
        samples=1000,
        covariance_classical=np.diag([4.0, 1e-6, 0.25, 9.0]),
    )
    corrections = SimpleNamespace(residual_noise=noise)
    k = scenario.dead_band_sigmas
    np.testing.assert_allclose(
        admittance_dead_band(scenario, "internal", corrections),
        np.maximum(scenario.dead_band, k * np.array([1e-3, 0.1, 0.2, 1.0])),
    )
    np.testing.assert_allclose(
        admittance_dead_band(scenario, "classical", corrections),
        np.maximum(scenario.dead_band, k * np.array([2.0, 1e-3, 0.5, 3.0])),
    )
    assert admittance_dead_band(scenario, "internal", None) == scenario.dead_band
    noise.covariance_classical = None
    assert admittance_dead_band(scenario, "classical", corrections) == scenario.dead_band
    noise.internal_gain = 2 * scenario.residual_gain
    with pytest.raises(ValueError, match="calibrate again"):
        admittance_dead_band(scenario, "internal", corrections)
