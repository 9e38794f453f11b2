"""No deprecated Drake feature: building and stepping each of the project's diagrams logs no
deprecation message and raises no ``DrakeDeprecationWarning``, on every tested Drake release.

Drake deprecates in two ways. C++ code logs "DRAKE_DEPRECATED: ..." through spdlog (and its
model parser logs "... is deprecated" for a deprecated SDFormat/URDF element), which pydrake
forwards to the Python logger named "drake"; Python bindings raise a
``DrakeDeprecationWarning``. Drake logs each C++ message only once per process (and pydrake
shows each warning once by default), so an earlier test of the same session could hide it:
every case therefore runs in a fresh Python process (this file run as a script, from the
repository root), which reports what it saw as one JSON line.

Positive controls check that each channel is seen, so that the check cannot pass silently.
They depend on the release (``models.drake_compat``):

* every release: a model with a deprecated SDFormat element (log channel), and a function
  deprecated with ``pydrake.common.deprecation.deprecated_callable``, the decorator pydrake
  deprecates its Python API with (warning channel);
* drake 1.51.1 also: a TAMSI plant (its C++ ``DRAKE_DEPRECATED`` log; TAMSI is removed in
  1.57) and ``Simulator.set_publish_every_time_step`` (a deprecated binding; removed by 1.58).
  Drake 1.58.0 deprecates nothing a Python program can reach: the one deprecation it
  documents, ``SingleOutputVectorSource``, has no Python binding.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from models.drake_compat import still_has

ROOT = Path(__file__).resolve().parents[1]
#: Simulated time each diagram is stepped, s (10 steps of the 1 ms plants).
STEP_TIME = 0.01


# --------------------------------------------------------------------------------------
# The cases: each builds one diagram (default settings, with a Meshcat when the builder
# takes one, so that the visualisation code is covered too), puts it in its initial state
# and steps a Simulator STEP_TIME. Run in the child process only.
# --------------------------------------------------------------------------------------


def _simulate(diagram, set_initial_state=None) -> None:
    from pydrake.systems.analysis import Simulator

    simulator = Simulator(diagram)
    if set_initial_state is not None:
        set_initial_state(simulator.get_mutable_context())
    simulator.Initialize()
    simulator.AdvanceTo(STEP_TIME)


def _meshcat():
    from pydrake.geometry import Meshcat

    return Meshcat()


def _case_humanoid_station() -> None:
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from diagrams.station.config import StationConfig
    from diagrams.station.humanoid_station import add_humanoid_station

    for model in ("hrp4_like", "nao_like"):
        builder = DiagramBuilder()
        station = add_humanoid_station(builder, StationConfig(model=model))
        posture = builder.AddSystem(ConstantVectorSource(station.q_hold))
        builder.Connect(posture.get_output_port(), station.desired_position)
        _simulate(builder.Build(), station.set_initial_state)


def _case_standing() -> None:
    from diagrams.station.standing import build_standing_diagram, set_initial_state

    for model in ("hrp4_like", "nao_like"):
        diagram, handles = build_standing_diagram(model, meshcat=_meshcat())
        _simulate(diagram, lambda context, d=diagram, h=handles: set_initial_state(d, context, h))


def _case_residual_comparison() -> None:
    from diagrams.residuals.residual_comparison import (
        ResidualComparisonScenario,
        build_residual_comparison_diagram,
        set_initial_state,
    )

    diagram, handles = build_residual_comparison_diagram(ResidualComparisonScenario(), _meshcat())
    _simulate(diagram, lambda context: set_initial_state(diagram, context, handles))


def _case_push_and_comply() -> None:
    from diagrams.residuals.push_and_comply import PushAndComplyScenario, build_push_and_comply_diagram

    for kind in ("internal", "classical"):
        diagram, handles = build_push_and_comply_diagram(PushAndComplyScenario(), kind, _meshcat())
        _simulate(diagram, handles.station.set_initial_state)


def _case_contact_localization() -> None:
    from diagrams.residuals.contact_study import ContactLocalizationScenario, build_contact_localization_diagram

    config = ContactLocalizationScenario(push_body="CHEST_Y_LINK", push_force=(-20.0, 0.0, 0.0), push_start=0.0)
    diagram, handles = build_contact_localization_diagram(config, _meshcat())
    _simulate(diagram, handles.station.set_initial_state)


def _case_nao_force_observer() -> None:
    from diagrams.observer.nao_force_observer import build_nao_force_observer_diagram, wide_stance
    from systems.simulation.disturbances import Push, SmoothPiecewise

    push = Push("torso", (0.05, 0.0, -0.05), (0.6, 0.0, 0.8), SmoothPiecewise((0.0, 1.0), (0.0, 3.0)))
    diagram, handles = build_nao_force_observer_diagram([push], posture=wide_stance(), meshcat=_meshcat())
    _simulate(diagram, handles.set_initial_state)


def _case_nao_walk() -> None:
    from diagrams.locomotion.nao_walk import build_nao_walk_diagram

    diagram, handles = build_nao_walk_diagram(meshcat=_meshcat())
    _simulate(diagram, handles.set_initial_state)


def _case_nao_walk_pulled() -> None:
    from diagrams.observer.nao_walk_pulled import build_nao_walk_pulled_diagram

    diagram, handles = build_nao_walk_pulled_diagram(meshcat=_meshcat())
    _simulate(diagram, handles.set_initial_state)


def _case_nao_compliant_arms() -> None:
    # The identified motor constants: identify_motor_constant() builds and runs its own diagram.
    from diagrams.observer.calibration import identified_motor_constants
    from diagrams.observer.nao_compliant_arms import build_nao_compliant_arms_diagram

    diagram, handles = build_nao_compliant_arms_diagram(
        motor_constants=dict(identified_motor_constants()), meshcat=_meshcat()
    )
    _simulate(diagram, handles.set_initial_state)


def _case_force_guided_walking() -> None:
    from diagrams.observer.nao_force_guided_walk import NaoForceGuidedWalkScenario, build_force_guided_diagram
    from systems.observer.force_guided_walking import TriggerParameters
    from systems.observer.force_observer import WALKING

    # GuidanceProfile()'s 5 N episodes, TriggerParameters()'s threshold, the walking preset.
    scenario = NaoForceGuidedWalkScenario(
        force=5.0, trigger=TriggerParameters(), preset="walking", force_rate_variance=WALKING.force_rate_variance
    )
    diagram, handles = build_force_guided_diagram(scenario, meshcat=_meshcat())
    _simulate(diagram, handles["station"].set_initial_state)


def _case_model_refinement() -> None:
    from diagrams.residuals.model_refinement import ModelRefinementScenario, build_refinement_diagram

    for residuals in (True, False):
        diagram, handles = build_refinement_diagram(ModelRefinementScenario(), None, residuals=residuals)
        _simulate(diagram, handles.station.set_initial_state)


def _case_estimate_from_log() -> None:
    """The offline path (``apps.estimate_from_log``): a short simulated log, estimated with the
    base state given and with the invariant EKF."""
    from dataclasses import replace

    from diagrams.residuals.log_estimation import build_estimator_plant, estimate_from_log, simulate_push_log

    log, _ = simulate_push_log("hrp4_like", duration=0.2, base_state="invariant_ekf")
    robot = build_estimator_plant("hrp4_like")
    estimate_from_log(robot, log)
    estimate_from_log(robot, replace(log, base_pose=None, base_velocity=None))


def _control_deprecated_model_element() -> None:
    """Positive control of the log channel on every release: a deprecated SDFormat element
    (libsdformat's element for testing deprecations) makes Drake's parser log "... is
    deprecated"."""
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    model = "<sdf version='1.9'><model name='m'><link name='l'/></model><_drake_deprecation_unit_test_element/></sdf>"
    plant = MultibodyPlant(1e-3)  # held: the parser keeps only a reference
    Parser(plant).AddModelsFromString(model, "sdf")


def _control_deprecated_callable() -> None:
    """Positive control of the warning channel on every release: a function deprecated with
    the decorator pydrake deprecates its Python API with."""
    from pydrake.common.deprecation import deprecated_callable

    deprecated_callable("use something else", date="2038-01-19")(lambda: None)()


def _control_tamsi_plant() -> None:
    """Positive control of the C++ DRAKE_DEPRECATED log: drake 1.51 deprecates TAMSI (removed
    in 1.57)."""
    from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
    from pydrake.systems.framework import DiagramBuilder

    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="tamsi"), builder)
    plant.Finalize()
    _simulate(builder.Build())


def _control_deprecated_binding() -> None:
    """Positive control of the warning channel by a binding drake 1.51 deprecates (gone in
    1.58)."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.primitives import ConstantVectorSource

    Simulator(ConstantVectorSource([1.0])).set_publish_every_time_step(False)


#: The controls by features drake 1.51 deprecates and later releases removed: whether the
#: installed release still has each (``models.drake_compat.REMOVED_IN``).
RELEASE_CONTROLS = {
    "tamsi_plant": still_has("TAMSI discrete contact solver"),
    "deprecated_binding": still_has("Simulator.set_publish_every_time_step"),
}
CASES = {name[len("_case_") :]: f for name, f in list(globals().items()) if name.startswith("_case_")}
CONTROLS = {name[len("_control_") :]: f for name, f in list(globals().items()) if name.startswith("_control_")}


def _run_in_this_process(name: str) -> dict:
    """Runs one case or control with both channels watched; returns what was seen."""
    import logging
    import traceback
    import warnings

    logged = []

    class _Collect(logging.Handler):
        def emit(self, record):
            logged.append(record.getMessage())

    from pydrake.common.deprecation import DrakeDeprecationWarning

    logger = logging.getLogger("drake")
    logger.addHandler(_Collect(level=logging.WARNING))
    if logger.getEffectiveLevel() > logging.WARNING:
        logger.setLevel(logging.WARNING)
    warning, error = None, None
    with warnings.catch_warnings():
        warnings.simplefilter("error", DrakeDeprecationWarning)
        try:
            {**CASES, **CONTROLS}[name]()
        except DrakeDeprecationWarning:
            warning = traceback.format_exc()
        except Exception:
            error = traceback.format_exc()
    return {
        "drake_deprecated": [m for m in logged if "deprecat" in m.lower()],
        "deprecation_warning": warning,
        "error": error,
    }


# --------------------------------------------------------------------------------------
# The tests: one child process per case, started together (their imports and model loads
# overlap) when the module's first test runs.
# --------------------------------------------------------------------------------------

_results: dict[str, dict] = {}


def _start(name: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH")))))
    return subprocess.Popen(
        [sys.executable, __file__, name], cwd=ROOT, env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )


def _result(name: str) -> dict:
    if not _results:  # first call: run them all, a few at a time (each loads Drake and a model)
        controls = [n for n in CONTROLS if RELEASE_CONTROLS.get(n, True)]
        pending, running = [*controls, *CASES], {}
        limit = max(2, min(4, os.cpu_count() or 2))
        while pending or running:
            while pending and len(running) < limit:
                n = pending.pop(0)
                running[n] = _start(n)
            n, process = next(iter(running.items()))
            del running[n]
            try:
                out, err = process.communicate(timeout=300)
            except subprocess.TimeoutExpired:
                process.kill()
                out, err = process.communicate()
            lines = [line for line in out.splitlines() if line.startswith("{")]
            _results[n] = (
                json.loads(lines[-1])
                if process.returncode == 0 and lines
                else {
                    "drake_deprecated": [],
                    "deprecation_warning": None,
                    "error": f"child process exited with {process.returncode}:\n{err[-4000:]}",
                }
            )
    return _results[name]


@pytest.mark.slow
def test_log_channel_positive_control():
    """A deprecated SDFormat element is logged as deprecated, and this test's handler sees it."""
    result = _result("deprecated_model_element")
    assert result["error"] is None, result["error"]
    assert any("_drake_deprecation_unit_test_element" in m for m in result["drake_deprecated"]), result


@pytest.mark.slow
def test_warning_channel_positive_control():
    result = _result("deprecated_callable")
    assert result["error"] is None, result["error"]
    assert result["deprecation_warning"] and "DrakeDeprecationWarning" in result["deprecation_warning"], result


@pytest.mark.skipif(
    not RELEASE_CONTROLS["tamsi_plant"], reason="this Drake has no TAMSI (deprecated in 1.51, removed in 1.57)"
)
def test_cpp_deprecation_log_positive_control():
    """A TAMSI plant logs DRAKE_DEPRECATED on drake 1.51, and this test's handler sees it."""
    result = _result("tamsi_plant")
    assert result["error"] is None, result["error"]
    assert any("DRAKE_DEPRECATED" in m and "TAMSI" in m for m in result["drake_deprecated"]), result


@pytest.mark.skipif(
    not RELEASE_CONTROLS["deprecated_binding"],
    reason="this Drake has no Simulator.set_publish_every_time_step (deprecated in 1.51, gone by 1.58)",
)
def test_deprecated_binding_positive_control():
    result = _result("deprecated_binding")
    assert result["error"] is None, result["error"]
    assert result["deprecation_warning"] and "set_publish_every_time_step" in result["deprecation_warning"], result


@pytest.mark.parametrize("case", list(CASES))
def test_diagram_uses_no_deprecated_drake_feature(case):
    result = _result(case)
    assert result["error"] is None, f"building or stepping '{case}' failed:\n{result['error']}"
    assert result["deprecation_warning"] is None, (
        f"'{case}' raised a DrakeDeprecationWarning:\n{result['deprecation_warning']}"
    )
    assert not result["drake_deprecated"], f"'{case}' logged: {result['drake_deprecated']}"


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    print(json.dumps(_run_in_this_process(sys.argv[1])))
