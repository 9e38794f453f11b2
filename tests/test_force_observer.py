"""Kalman force observer (Hawley et al. 2019) against the authors' own output on real Nao
recordings, plus the observer's behaviour and input checks."""

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from apps import replay_nao_dataset
from systems.observer import nao_dataset
from systems.observer.force_observer import (
    STANDING,
    LipForceObserver,
    LipObserverParameters,
    calibrated_normal_force,
    transition_matrices,
)

RECORDINGS = nao_dataset.RECORDINGS


@pytest.fixture(scope="module")
def dataset() -> Path:
    """The authors' recordings (shipped in data/hawley2019-nao): a missing folder fails the
    real-data tests with an error naming the path, it never skips them."""
    return nao_dataset.published_dataset_dir()


def test_published_recordings_ship_with_the_repository(monkeypatch):
    monkeypatch.delenv(nao_dataset.DATA_DIR_VARIABLE, raising=False)
    directory = nao_dataset.published_dataset_dir()
    assert directory == Path(__file__).resolve().parents[1] / "data" / "hawley2019-nao"
    for name in RECORDINGS:
        assert sorted(p.name for p in (directory / name).iterdir()) == [
            "Acc.mat",
            "CoM_Pos.mat",
            "ZMP.mat",
            "reference_F.csv",
            "total_force.mat",
        ]
    notice = (directory / "README.md").read_text()
    assert "wael-suleiman-UdeS/External_Force_ROS_Package" in notice and "GPL-2.0" in notice


def test_environment_variable_points_at_other_recordings_or_fails_clearly(monkeypatch, tmp_path):
    variable = nao_dataset.DATA_DIR_VARIABLE
    mine = tmp_path / "datasets" / "hawley2019-nao"
    for name in RECORDINGS:
        shutil.copytree(nao_dataset.BUNDLED_DATASET_DIR / name, mine / name)
    monkeypatch.setenv(variable, str(tmp_path))
    assert nao_dataset.published_dataset_dir() == mine

    shutil.rmtree(mine / "Force_Z_data")
    with pytest.raises(
        nao_dataset.DatasetError, match=re.escape(f"'{mine / 'Force_Z_data'}' is not a folder") + f".*{variable}"
    ):
        nao_dataset.published_dataset_dir()

    monkeypatch.setenv(variable, str(tmp_path / "nowhere"))
    with pytest.raises(
        nao_dataset.DatasetError,
        match=re.escape(f"'{tmp_path / 'nowhere' / 'datasets' / 'hawley2019-nao'}' is not a folder"),
    ):
        nao_dataset.published_dataset_dir()


@pytest.mark.parametrize("name", RECORDINGS)
def test_reproduces_the_authors_implementation_on_real_nao_data(name, dataset, tmp_path, capsys):
    """reference_F.csv is the authors' MATLAB observer run on the same recording (Octave)."""
    assert replay_nao_dataset.main([str(dataset / name), "--out", str(tmp_path)]) == 0
    out = tmp_path / "replay_nao_dataset" / name
    estimates = np.loadtxt(out / "estimates.csv", delimiter=",", skiprows=1)
    reference = np.loadtxt(dataset / name / "reference_F.csv", delimiter=",")
    assert estimates.shape == (len(reference), 4)
    np.testing.assert_allclose(estimates[:, 0], STANDING.period * np.arange(1, len(reference) + 1), rtol=1e-12)
    assert np.abs(estimates[:, 1:] - reference).max() < 1e-9 * np.abs(reference).max()
    assert (out / "estimates.png").stat().st_size > 10_000
    assert (out / "estimates.csv").read_text().startswith("t,Fx,Fy,Fz\n")


@pytest.mark.parametrize(
    "name, expected",
    [("Force_Y_data", (0.0, -10.96, 0.0)), ("Force_Z_data", (2.22, -4.16, -11.12))],
)
def test_estimates_the_papers_loads_on_real_data(name, expected, dataset):
    """While loaded, every component's median is within 1.0 N of the paper's expected virtual
    force (eq. 24; the issue's floor is 1.5 N; measured: at most 0.89 N off). The loaded
    samples are chosen from the observer's inputs, not its output: those where the measured
    ZMP has moved from under the CoM by at least 80 % of what the expected force moves it
    in the LIP model (eq. 10: |ZMP - CoM| = z_c |F_xy| / (M g - F_z)), so an observer that
    underestimates the load fails here."""
    data = nao_dataset.load_recording(dataset / name)
    com = data["Xc_Yc_Zc"]
    offset = data["ZMP"] - com[:, :2]
    shift = np.linalg.norm(offset - offset[0], axis=1)
    force = np.asarray(expected)
    lip_shift = com[0, 2] * np.linalg.norm(force[:2]) / (STANDING.mass * STANDING.gravity - force[2])
    loaded = shift >= 0.8 * lip_shift
    assert loaded.sum() > 300
    forces = nao_dataset.replay(dataset / name)
    np.testing.assert_array_less(np.abs(np.median(forces[loaded], axis=0) - force), 1.0)


def test_observer_converges_to_a_constant_force_on_a_synthetic_lip():
    """LIP statics: a constant horizontal force F_x at CoM height z shifts the ZMP by
    -z F_x / f_n (eq. 10 with f_n = -M g); the observer recovers F_x."""
    M, g, z = STANDING.mass, STANDING.gravity, 0.3
    Fx, Fy = 3.0, -2.0
    fn = -M * g
    observer = LipForceObserver()
    com, acc = np.array([0.01, 0.0, z]), np.zeros(3)
    zmp = np.array([com[0] - z / fn * Fx, com[1] - z / fn * Fy])
    for _ in range(600):
        F, valid = observer.update(com, acc, zmp, fn)
    assert valid and np.allclose(F[:2], [Fx, Fy], atol=0.02) and abs(F[2]) < 1e-6


def test_lifted_robot_is_flagged_invalid_instead_of_dividing_by_zero():
    observer = LipForceObserver()
    com, acc = np.array([0.0, 0.0, 0.3]), np.zeros(3)
    for _ in range(5):
        observer.update(com, acc, np.zeros(2), -STANDING.mass * STANDING.gravity)
    for _ in range(400):  # feet off the ground: the FSRs read 0
        F, valid = observer.update(com, acc, np.zeros(2), 0.0)
    assert not valid and np.all(np.isfinite(F))


def test_model_matrices_and_parameter_checks():
    A, B = transition_matrices(0.5)
    assert A[0, 2] == 0.125 and A[3, 4] == 0.5 and B[0, 0] == 0.5**3 / 6 and B[3, 1] == 0.125
    with pytest.raises(ValueError, match="period"):
        LipObserverParameters(period=0.0)
    with pytest.raises(ValueError, match="R_z"):
        LipObserverParameters(R_z=((1, 0, 0), (0, -1, 0), (0, 0, 1)))
    with pytest.raises(ValueError, match="first sample"):
        calibrated_normal_force(np.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="zmp"):
        LipForceObserver().update(np.zeros(3), np.zeros(3), [np.nan, 0.0], -50.0)


def _copy(dataset: Path, tmp_path: Path) -> Path:
    target = tmp_path / "recording"
    shutil.copytree(dataset / "Force_Y_data", target)
    return target


def test_clear_errors_for_broken_recordings(dataset, tmp_path, capsys):
    recording = _copy(dataset, tmp_path)
    (recording / "Acc.mat").unlink()
    assert replay_nao_dataset.main([str(recording), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "missing file" in err and "Acc.mat" in err

    recording = _copy(dataset, tmp_path / "b")
    scipy.io.savemat(recording / "ZMP.mat", {"zmp_wrong": np.zeros((5, 2))})
    with pytest.raises(nao_dataset.DatasetError, match="no variable 'ZMP'"):
        nao_dataset.load_recording(recording)

    recording = _copy(dataset, tmp_path / "c")
    acc = scipy.io.loadmat(recording / "Acc.mat")["acc"][:-3]
    scipy.io.savemat(recording / "Acc.mat", {"acc": acc})
    with pytest.raises(nao_dataset.DatasetError, match="different lengths"):
        nao_dataset.load_recording(recording)

    recording = _copy(dataset, tmp_path / "d")
    com = scipy.io.loadmat(recording / "CoM_Pos.mat")["Xc_Yc_Zc"]
    com[[4, 9]] = np.nan
    scipy.io.savemat(recording / "CoM_Pos.mat", {"Xc_Yc_Zc": com})
    with pytest.raises(nao_dataset.DatasetError, match="NaN or inf in rows 5, 10"):
        nao_dataset.load_recording(recording)

    recording = _copy(dataset, tmp_path / "e")
    (recording / "total_force.mat").write_bytes(b"not a mat file")
    with pytest.raises(nao_dataset.DatasetError, match="cannot read"):
        nao_dataset.load_recording(recording)


def test_drake_system_matches_the_core_on_real_data(dataset):
    """LipForceObserverSystem, stepped by its own periodic update, equals the numpy core
    (and so the authors' output) on the first 300 samples of a real recording."""
    from systems.observer.force_observer import LipForceObserverSystem

    data = nao_dataset.load_recording(dataset / "Force_Z_data")
    normal_force = calibrated_normal_force(data["total_force"].sum(axis=1))
    reference = np.loadtxt(dataset / "Force_Z_data" / "reference_F.csv", delimiter=",")
    system = LipForceObserverSystem()
    context = system.CreateDefaultContext()
    for k in range(300):
        system.GetInputPort("com_position").FixValue(context, data["Xc_Yc_Zc"][k])
        system.GetInputPort("com_acceleration").FixValue(context, data["acc"][k])
        system.GetInputPort("zmp").FixValue(context, data["ZMP"][k])
        system.GetInputPort("normal_force").FixValue(context, [normal_force[k]])
        context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
        force = system.GetOutputPort("virtual_force").Eval(context)
        assert np.abs(force - reference[k]).max() < 1e-9 * max(1.0, np.abs(reference[k]).max()), k
    assert system.GetOutputPort("valid").Eval(context)[0] == 1.0
    system.GetInputPort("zmp").FixValue(context, [np.nan, 0.0])
    with pytest.raises(ValueError, match="input 'zmp' has NaN"):
        system.EvalUniquePeriodicDiscreteUpdate(context)


def test_core_state_round_trips():
    """LipForceObserver.state()/set_state() carry the filters exactly (what the Drake wrapper
    keeps in its context)."""
    from systems.observer.force_observer import FILTER_STATE_SIZE, LipForceObserverSystem

    observer = LipForceObserver(STANDING)
    with pytest.raises(RuntimeError, match="no filter state"):
        observer.state()
    observer.reset([0.01, 0.0, 0.26], [0.0, 0.0, 0.0])
    for _ in range(3):
        observer.update([0.01, 0.0, 0.26], [0.1, 0.0, 0.0], [0.0, 0.0], -STANDING.mass * STANDING.gravity)
    saved = observer.state()
    assert saved.shape == (3, FILTER_STATE_SIZE)
    copy = LipForceObserver(STANDING)
    copy.set_state(saved)
    args = ([0.01, 0.0, 0.26], [0.2, 0.0, 0.0], [0.01, 0.0], -STANDING.mass * STANDING.gravity)
    assert copy.update(*args)[0].tolist() == observer.update(*args)[0].tolist()
    with pytest.raises(ValueError, match="finite"):
        copy.set_state(np.full((3, FILTER_STATE_SIZE), np.nan))
    system = LipForceObserverSystem()
    context = system.CreateDefaultContext()
    assert system.GetOutputPort("virtual_force").Eval(context).tolist() == [0.0, 0.0, 0.0]  # before the first update
