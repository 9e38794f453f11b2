"""Model identification from a calibration log (systems.estimation.model_identification),
against physics: the regressor against Drake's inverse dynamics and Pinocchio's own
regressor, the base-parameter map, and the identification of KNOWN corrections from a log
that Drake's inverse dynamics computes on the TRUE (perturbed) model."""

import copy
import dataclasses

import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    BodyIndex,
    FixedOffsetFrame,
    JacobianWrtVariable,
    MultibodyForces,
    RevoluteJoint,
    SpatialInertia,
)
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from models import add_humanoid, set_standing_state
from systems.common.topology import floating_base_topology
from systems.estimation.model_identification import (
    CalibrationLog,
    CorrectedJointTorque,
    IdentificationOptions,
    InertialParameterRegressor,
    ModelCorrections,
    base_parameter_map,
    identify_model_corrections,
    inertial_parameters,
    newton_euler_matrix,
    stance_base_velocity,
)
from systems.residuals.contact_estimation import SOLE_SHEAR_AND_YAW
from systems.simulation.imperfections import (
    ModelMismatch,
    friction_torque,
    perturbed_spatial_inertias,
    rated_joint_torques,
    torque_measurement_errors,
)

#: The calibration motion: 15 s at 200 Hz, regression every 25 ms (560 samples).
DURATION, RATE, DECIMATION = 15.0, 200.0, 0.025
#: A standing posture that is NOT in the training log (arms and chest moved).
TEST_POSTURE = {"R_SHOULDER_P": -0.6, "L_SHOULDER_P": 0.3, "CHEST_P": 0.1, "R_ELBOW_P": -0.4}


@pytest.fixture(scope="module")
def hrp4():
    plant = MultibodyPlant(0.0)
    handles = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    return plant, handles


@pytest.fixture(scope="module")
def regressor(hrp4):
    return InertialParameterRegressor(hrp4[0])


def _random_state(plant, rng):
    q = np.zeros(plant.num_positions())
    q[:4] = rng.standard_normal(4)
    q[:4] /= np.linalg.norm(q[:4])
    q[4:7] = rng.standard_normal(3)
    q[7:] = rng.uniform(-0.8, 0.8, q.size - 7)
    return q, rng.standard_normal(plant.num_velocities()), rng.standard_normal(plant.num_velocities())


def _inverse_dynamics_minus_gravity(plant, context, q, v, vdot):
    """M vdot + C v - tau_g by Drake (M holds the reflected inertia)."""
    plant.SetPositions(context, q)
    plant.SetVelocities(context, v)
    return plant.CalcInverseDynamics(context, vdot, MultibodyForces(plant)) - plant.CalcGravityGeneralizedForces(
        context
    )


# ---------------------------------------------------------------------------------------
# The regressor.
# ---------------------------------------------------------------------------------------


def test_regressor_reproduces_drake_inverse_dynamics(hrp4, regressor):
    plant, _ = hrp4
    context = plant.CreateDefaultContext()
    rng = np.random.default_rng(0)
    pi = regressor.parameters()
    assert regressor.regressor(*_random_state(plant, rng)).shape == (plant.num_velocities(), 10 * 37)
    for _ in range(5):
        q, v, vdot = _random_state(plant, rng)
        expected = _inverse_dynamics_minus_gravity(plant, context, q, v, vdot)
        predicted = regressor.regressor(q, v, vdot) @ pi + regressor.reflected_inertia * vdot
        assert np.max(np.abs(predicted - expected)) < 1e-9 * np.max(np.abs(expected))


def test_regressor_is_linear_in_the_parameters(hrp4, regressor):
    """Y (pi1 + pi2) = ID(pi1) + ID(pi2) (gravity included, reflected inertia once)."""
    plant, _ = hrp4
    rng = np.random.default_rng(1)
    inertias = [perturbed_spatial_inertias(plant, ModelMismatch(30.0, 30.0, 30.0), seed) for seed in (1, 2)]
    q, v, vdot = _random_state(plant, rng)
    tau = []
    for inertia in inertias:
        context = plant.CreateDefaultContext()
        for index, M in inertia.items():
            plant.get_body(BodyIndex(index)).SetSpatialInertiaInBodyFrame(context, M)
        tau.append(_inverse_dynamics_minus_gravity(plant, context, q, v, vdot) - regressor.reflected_inertia * vdot)
    Y = regressor.regressor(q, v, vdot)
    both = Y @ (regressor.parameters(inertias[0]) + regressor.parameters(inertias[1]))
    assert np.max(np.abs(both - (tau[0] + tau[1]))) < 1e-9 * np.max(np.abs(both))


def _pinocchio_acceleration(oracle, q, v, vdot):
    """Pinocchio's a (free flyer: d/dt [v_local; w_local]) from Drake's world-aligned vdot."""
    q_pin, v_pin = oracle.to_pinocchio(q, v)
    a_pin = np.zeros(oracle.model.nv)
    a_pin[oracle.perm] = vdot
    R = oracle.R_W_Fw @ _rotation(q[:4])
    ff = oracle.model.joints[oracle.model.getJointId(oracle.free_joint_name)]
    w_B, v_B = R.T @ v[:3], R.T @ v[3:6]
    a_pin[ff.idx_v : ff.idx_v + 3] = R.T @ vdot[3:6] - np.cross(w_B, v_B)
    a_pin[ff.idx_v + 3 : ff.idx_v + 6] = R.T @ vdot[:3]
    return q_pin, v_pin, a_pin, R


def _rotation(wxyz):
    w, x, y, z = wxyz / np.linalg.norm(wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _pinocchio_rows_to_drake(oracle, Y_pin, R):
    """Rows of a Pinocchio generalized force ([f_local; n_local] base) to Drake's [n_W; f_W]."""
    Y = oracle.vector_to_ours(Y_pin)  # rows [n_local; f_local; joints]
    Y[0:3], Y[3:6] = R @ Y[0:3], R @ Y[3:6]
    return Y


def test_regressor_matches_pinocchio_regressor(hrp4, regressor):
    """Pinocchio's computeJointTorqueRegressor (an independent implementation): the products
    Y pi agree, and one body's 10 columns span the same space as its Pinocchio joint's, with
    the parameter map taking the Drake body parameters to Pinocchio's (about the joint
    origin, [m, mc, Ixx, Ixy, Iyy, Ixz, Iyz, Izz])."""
    pin = pytest.importorskip("pinocchio")
    from tests.pinocchio_oracle import build_pinocchio_oracle

    plant, _ = hrp4
    oracle = build_pinocchio_oracle(plant)
    model, data = oracle.model, oracle.data
    pi_pin = np.concatenate([model.inertias[j].toDynamicParameters() for j in range(1, model.njoints)])
    pi = regressor.parameters()
    body = plant.GetBodyByName("R_ELBOW_P_LINK")
    joint_id, _ = oracle.body_placement[body.index()]
    assert sum(1 for j, _ in oracle.body_placement.values() if j == joint_id) == 1  # alone on its joint
    k = list(regressor.body_indices).index(int(body.index()))
    rng = np.random.default_rng(2)
    blocks_drake, blocks_pin = [], []
    for _ in range(12):
        q, v, vdot = _random_state(plant, rng)
        q_pin, v_pin, a_pin, R = _pinocchio_acceleration(oracle, q, v, vdot)
        Y_pin = _pinocchio_rows_to_drake(oracle, pin.computeJointTorqueRegressor(model, data, q_pin, v_pin, a_pin), R)
        Y = regressor.regressor(q, v, vdot)
        assert np.max(np.abs(Y @ pi - Y_pin @ pi_pin)) < 1e-9 * np.max(np.abs(Y @ pi))
        blocks_drake.append(Y[:, 10 * k : 10 * k + 10])
        blocks_pin.append(Y_pin[:, 10 * (joint_id - 1) : 10 * joint_id])
    Yd, Yp = np.vstack(blocks_drake), np.vstack(blocks_pin)
    T, *_ = np.linalg.lstsq(Yp, Yd, rcond=None)  # Yd = Yp T: pi_joint = T pi_body
    assert np.linalg.matrix_rank(Yd) == np.linalg.matrix_rank(Yp) == np.linalg.matrix_rank(np.hstack((Yd, Yp)))
    assert np.max(np.abs(Yp @ T - Yd)) < 1e-9 * np.max(np.abs(Yd))
    pi_body = pi[10 * k : 10 * k + 10]
    np.testing.assert_allclose(T @ pi_body, pi_pin[10 * (joint_id - 1) : 10 * joint_id], atol=1e-9)


def test_spatial_inertias_round_trip(hrp4, regressor):
    plant, _ = hrp4
    pi = regressor.parameters()
    back = regressor.parameters(regressor.spatial_inertias(pi))
    np.testing.assert_allclose(back, pi, atol=1e-12)


# ---------------------------------------------------------------------------------------
# Base parameters.
# ---------------------------------------------------------------------------------------


def _planar_arm():
    """A fixed-base 2R arm, both hinges along z (parallel to gravity, which then does no
    work), the second 0.4 m along link 1's x: a horizontal planar arm."""
    plant = MultibodyPlant(0.0)
    links = [plant.AddRigidBody(f"l{i}", SpatialInertia.SolidBoxWithMass(1.0 + i, 0.4, 0.05, 0.05)) for i in range(2)]
    elbow = plant.AddFrame(FixedOffsetFrame("elbow", links[0].body_frame(), RigidTransform([0.4, 0.0, 0.0])))
    plant.AddJoint(RevoluteJoint("j0", plant.world_frame(), links[0].body_frame(), [0.0, 0.0, 1.0]))
    plant.AddJoint(RevoluteJoint("j1", elbow, links[1].body_frame(), [0.0, 0.0, 1.0]))
    plant.Finalize()
    return plant, links


def test_base_parameter_map_reproduces_the_regressor():
    """A horizontal planar 2R arm has 4 base parameters of its 20 (Khalil & Dombre, ch. 12:
    ZZ1R = ZZ1 + m2 l1^2, ZZ2, MX2, MY2); Y pi = Y_ind pi_base for random pi on fresh
    samples. (The arm has no floating base: its regressor is (R2) written out here with
    the module's Newton-Euler matrix.)"""
    plant, links = _planar_arm()
    context = plant.CreateDefaultContext()
    world = plant.world_frame()
    g = plant.gravity_field().gravity_vector()
    rng = np.random.default_rng(3)

    def regressor(q, v, vdot):
        plant.SetPositions(context, q)
        plant.SetVelocities(context, v)
        acc = plant.CalcSpatialAccelerationsFromVdot(context, vdot)
        columns = []
        for link in links:
            R = plant.EvalBodyPoseInWorld(context, link).rotation().matrix()
            V = plant.EvalBodySpatialVelocityInWorld(context, link)
            A = acc[int(link.index())]
            E = newton_euler_matrix(R.T @ V.rotational(), R.T @ A.rotational(), R.T @ (A.translational() - g))
            J = plant.CalcJacobianSpatialVelocity(
                context, JacobianWrtVariable.kV, link.body_frame(), np.zeros(3), world, world
            )
            columns.append(J.T @ np.vstack((R @ E[:3], R @ E[3:])))
        return np.hstack(columns)

    q, v, vdot = rng.standard_normal((3, 2))
    pi = np.concatenate([inertial_parameters(link.default_spatial_inertia()) for link in links])
    expected = plant.CalcInverseDynamics(context, vdot, MultibodyForces(plant))  # gravity does no work
    np.testing.assert_allclose(regressor(q, v, vdot) @ pi, expected, atol=1e-12)
    Y = np.vstack([regressor(*rng.standard_normal((3, 2))) for _ in range(40)])
    base = base_parameter_map(Y)
    assert base.rank == 4
    for _ in range(5):
        pi = rng.standard_normal(Y.shape[1])
        Y_new = regressor(*rng.standard_normal((3, 2)))
        np.testing.assert_allclose(Y_new @ pi, base.reduce(Y_new) @ base.base_parameters(pi), atol=1e-9)


def test_base_parameters_of_the_humanoid(hrp4, regressor):
    plant, _ = hrp4
    rng = np.random.default_rng(4)
    Y = np.vstack([regressor.regressor(*_random_state(plant, rng)) for _ in range(30)])
    base = base_parameter_map(Y, tol=1e-9)
    assert base.rank < 10 * regressor.num_bodies
    pi = rng.standard_normal(Y.shape[1])
    Y_new = regressor.regressor(*_random_state(plant, rng))
    np.testing.assert_allclose(Y_new @ pi, base.reduce(Y_new) @ base.base_parameters(pi), atol=1e-8)
    print(f"hrp4_like: {base.rank} base parameters of {Y.shape[1]}")


# ---------------------------------------------------------------------------------------
# Identification from a synthetic log computed on the TRUE model.
# ---------------------------------------------------------------------------------------


def _synthetic_log(plant, handles, true_inertias, seed=1):
    """A standing robot (base fixed at the standing pose) moving every joint slowly (three
    sines per joint, 0.1-0.7 Hz, 0.05-0.12 rad each); Drake's inverse dynamics of the TRUE
    model with gravity and joint damping; the base's whole generalized force comes from the
    two F/T frames (minimum-norm split), the joints' from the motors through Coulomb +
    viscous friction; the motor torques read with a scale and offset error."""
    rng = np.random.default_rng(seed)
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, handles)
    q0 = plant.GetPositions(context).copy()
    for index, M in true_inertias.items():
        plant.get_body(BodyIndex(index)).SetSpatialInertiaInBodyFrame(context, M)
    n = plant.num_velocities() - 6
    t = np.arange(0.0, DURATION, 1.0 / RATE)
    amp, freq, phase = rng.uniform(0.05, 0.12, (n, 3)), rng.uniform(0.1, 0.7, (n, 3)), rng.uniform(0, 6.3, (n, 3))
    arg = 2 * np.pi * freq * t[:, None, None] + phase
    q = np.tile(q0, (t.size, 1))
    q[:, 7:] += (amp * np.sin(arg)).sum(-1)
    v, vdot = np.zeros((t.size, n + 6)), np.zeros((t.size, n + 6))
    v[:, 6:] = (amp * 2 * np.pi * freq * np.cos(arg)).sum(-1)
    vdot[:, 6:] = -(amp * (2 * np.pi * freq) ** 2 * np.sin(arg)).sum(-1)
    rated = rated_joint_torques(plant)
    truth = {"coulomb": 0.03 * rated, "viscous": 0.02 * rated}
    scale, truth["offset"] = torque_measurement_errors(rated, 5.0, 1.0, seed)
    truth["scale"] = scale - 1.0
    frames = [handles.ft_sensor_frames["left"], handles.ft_sensor_frames["right"]]
    world = plant.world_frame()
    measured, wrenches = np.zeros((t.size, n)), np.zeros((t.size, 12))
    for k in range(t.size):
        plant.SetPositions(context, q[k])
        plant.SetVelocities(context, v[k])
        forces = MultibodyForces(plant)
        plant.CalcForceElementsContribution(context, forces)  # gravity and joint damping
        total = plant.CalcInverseDynamics(context, vdot[k], forces)
        J = [
            plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, f, np.zeros(3), world, world)
            for f in frames
        ]
        W = np.linalg.lstsq(np.hstack([Ji[:, :6].T for Ji in J]), total[:6], rcond=None)[0]
        tau = total[6:] - sum(Ji[:, 6:].T @ W[6 * s : 6 * s + 6] for s, Ji in enumerate(J))
        tau -= friction_torque(v[k, 6:], truth["coulomb"], truth["viscous"], 0.1)
        measured[k] = scale * tau + truth["offset"]
        wrenches[k] = W
    log = CalibrationLog(time=t, q=q, v=v, measured_torque=measured, known_wrenches=wrenches)
    return log, truth, frames


def _standing_gravity(plant, handles, inertias):
    """(base rows of tau_g: [moment about the base origin; force], world; total mass; CoM)
    at TEST_POSTURE with ``inertias`` in the context."""
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, handles)
    for name, dq in TEST_POSTURE.items():
        joint = plant.GetJointByName(name)
        joint.set_angle(context, joint.get_angle(context) + dq)
    for index, M in inertias.items():
        plant.get_body(BodyIndex(index)).SetSpatialInertiaInBodyFrame(context, M)
    g = plant.CalcGravityGeneralizedForces(context)[:6]
    return g, plant.CalcTotalMass(context), plant.CalcCenterOfMassPositionInWorld(context)


@pytest.fixture(scope="module")
def calibration(hrp4):
    plant, handles = hrp4
    true = perturbed_spatial_inertias(plant, ModelMismatch(mass_percent=5, com_percent=10, inertia_percent=0), 7)
    log, truth, frames = _synthetic_log(plant, handles, true)
    return true, log, truth, frames


def _torque_std(plant):
    return 0.00125 * rated_joint_torques(plant) + 1e-3  # N m: a quarter of the added noise


def _check_gravity(plant, handles, true, corrections, label):
    (g_nom, m_nom, c_nom), (g_true, m_true, c_true), (g_corr, m_corr, c_corr) = (
        _standing_gravity(plant, handles, inertias) for inertias in ({}, true, corrections.spatial_inertias)
    )
    force_reduction = 1 - np.linalg.norm(g_corr[3:] - g_true[3:]) / np.linalg.norm(g_nom[3:] - g_true[3:])
    moment_reduction = 1 - np.linalg.norm(g_corr[:3] - g_true[:3]) / np.linalg.norm(g_nom[:3] - g_true[:3])
    print(
        f"{label}: weight error {100 * (m_corr / m_true - 1):+.5f} % (nominal {100 * (m_nom / m_true - 1):+.3f} %), "
        f"CoM xy error {1e3 * np.linalg.norm((c_corr - c_true)[:2]):.3f} mm (nominal "
        f"{1e3 * np.linalg.norm((c_nom - c_true)[:2]):.3f} mm); spurious base force reduced by "
        f"{100 * force_reduction:.2f} %, base moment by {100 * moment_reduction:.2f} %; {corrections.diagnostics}"
    )
    return m_corr / m_true - 1, np.linalg.norm((c_corr - c_true)[:2]), force_reduction, moment_reduction


def test_identification_recovers_known_corrections(hrp4, calibration):
    """Noise-free: the model class holds the truth up to the rotational inertias (nominal
    here, the truth's about the body origin moves with the CoM), so the floors are set by
    that: weight within 0.01 % (measured 2e-5 %), CoM within 0.1 mm (measured 0.002 mm),
    standing base force and moment errors reduced by >= 90 % (measured 100 %, 99.9 %),
    friction within 5 % (measured <= 0.45 %), scale within 0.01 (0.004), offset within 2 %
    of the rated torque (0.05 %)."""
    plant, handles = hrp4
    true, log, truth, frames = calibration
    options = IdentificationOptions(decimation_period=DECIMATION, torque_std=_torque_std(plant))
    corrections = identify_model_corrections(plant, log, known_wrench_frames=frames, options=options)
    weight, com, force_reduction, moment_reduction = _check_gravity(plant, handles, true, corrections, "noise-free")
    assert abs(weight) < 1e-4
    assert com < 1e-4
    assert force_reduction >= 0.9 and moment_reduction >= 0.9
    rated = rated_joint_torques(plant)
    errors = {
        "coulomb": np.max(np.abs(corrections.coulomb / truth["coulomb"] - 1)),
        "viscous": np.max(np.abs(corrections.viscous / truth["viscous"] - 1)),
        "scale": np.max(np.abs(corrections.torque_scale - truth["scale"])),
        "offset/rated": np.max(np.abs(corrections.torque_offset - truth["offset"]) / rated),
    }
    print("noise-free joint errors:", {k: round(float(e), 5) for k, e in errors.items()})
    assert errors["coulomb"] < 0.05 and errors["viscous"] < 0.05
    assert errors["scale"] < 0.01 and errors["offset/rated"] < 0.02
    d = corrections.diagnostics
    assert d["rms_after"]["base_force"] < 0.01 * d["rms_before"]["base_force"]
    assert d["rms_after"]["joints"] < 0.01 * d["rms_before"]["joints"]
    assert d["num_clipped_masses"] == 0
    assert all(M.get_mass() > 0 for M in corrections.spatial_inertias.values())


@pytest.mark.slow
def test_identification_with_noise(hrp4, calibration):
    """White noise on the torques (0.5 % of the rated torque), the F/T wrenches (1 N,
    0.1 N m) and every velocity (0.01 rad/s, m/s; the base's too, so its noise enters the
    regressor as errors in variables). With the prior on link deviations (10 %), the
    spurious standing base force still falls by >= 70 % (measured 99.6 %), the weight error
    stays < 0.1 % (measured 0.01 %); the base moment (CoM x/y) falls by >= 50 % (measured
    74 % on this 15 s log, 56-71 % on 20 s variants of it during development: the
    base-velocity noise is the limit).
    Coulomb friction within 15 % on joints rated >= 40 N m (measured 10.5 %: the arm
    chains' masses and torque scales are tied and the F/T sensors see the arms weakly)."""
    plant, handles = hrp4
    true, log, truth, frames = calibration
    rng = np.random.default_rng(5)
    noisy = copy.copy(log)
    noisy.measured_torque = log.measured_torque + 0.005 * rated_joint_torques(plant) * rng.standard_normal(
        log.measured_torque.shape
    )
    noisy.known_wrenches = log.known_wrenches + np.tile([0.1] * 3 + [1.0] * 3, 2) * rng.standard_normal(
        log.known_wrenches.shape
    )
    noisy.v = log.v + 0.01 * rng.standard_normal(log.v.shape)
    options = IdentificationOptions(decimation_period=DECIMATION, torque_std=_torque_std(plant), inertial_prior_std=0.1)
    corrections = identify_model_corrections(plant, noisy, known_wrench_frames=frames, options=options)
    weight, com, force_reduction, moment_reduction = _check_gravity(plant, handles, true, corrections, "noisy")
    assert abs(weight) < 1e-3
    assert force_reduction >= 0.7
    assert moment_reduction >= 0.5
    big = rated_joint_torques(plant) >= 40.0  # legs, chest, shoulders, elbows
    coulomb = np.abs(corrections.coulomb / truth["coulomb"] - 1)
    print(f"noisy: Coulomb error max {coulomb.max():.3f}, on joints rated >= 40 N m {coulomb[big].max():.3f}")
    assert coulomb[big].max() < 0.15


# ---------------------------------------------------------------------------------------
# Corrections: evaluation, persistence, the Drake system.
# ---------------------------------------------------------------------------------------


def _corrections(n=3):
    return ModelCorrections(
        spatial_inertias={1: SpatialInertia.SolidBoxWithMass(2.0, 0.1, 0.2, 0.3)},
        coulomb=np.array([1.0, 0.5, 0.0][:n]),
        viscous=np.array([0.2, 0.1, 0.0][:n]),
        smoothing_velocity=0.1,
        torque_offset=np.array([0.3, -0.2, 0.0][:n]),
        torque_scale=np.array([0.05, -0.1, 0.0][:n]),
        body_names={1: "box"},
        diagnostics={"rank": 4},
    )


def test_corrected_torque_formula_and_shapes():
    c = _corrections()
    tau_m, qdot = np.array([10.0, -4.0, 1.0]), np.array([0.2, -0.05, 3.0])
    expected = (tau_m - c.torque_offset) / (1 + c.torque_scale) - c.coulomb * np.tanh(qdot / 0.1) - c.viscous * qdot
    np.testing.assert_allclose(c.corrected_torque(tau_m, qdot), expected)
    stacked = c.corrected_torque(np.tile(tau_m, (4, 1)), np.tile(qdot, (4, 1)))
    assert stacked.shape == (4, 3)
    np.testing.assert_allclose(stacked[2], expected)


def test_corrections_save_and_load(tmp_path):
    c = _corrections()
    path = tmp_path / "corrections.npz"
    c.save(path)
    back = ModelCorrections.load(path)
    for name in ("coulomb", "viscous", "torque_offset", "torque_scale"):
        np.testing.assert_array_equal(getattr(back, name), getattr(c, name))
    assert back.smoothing_velocity == 0.1 and back.body_names == {1: "box"} and back.diagnostics == {"rank": 4}
    np.testing.assert_allclose(
        back.spatial_inertias[1].CopyToFullMatrix6(), c.spatial_inertias[1].CopyToFullMatrix6(), atol=1e-14
    )
    bad = tmp_path / "bad.npz"
    bad.write_text("not a zip")
    with pytest.raises(ValueError, match="bad.npz"):
        ModelCorrections.load(bad)


def test_corrected_joint_torque_system(hrp4):
    plant, _ = hrp4
    n = floating_base_topology(plant).num_joints
    rng = np.random.default_rng(6)
    c = ModelCorrections(
        spatial_inertias={},
        coulomb=rng.uniform(0, 1, n),
        viscous=rng.uniform(0, 1, n),
        smoothing_velocity=0.1,
        torque_offset=rng.normal(0, 0.5, n),
        torque_scale=rng.normal(0, 0.05, n),
    )
    tau_m = rng.normal(0, 5, n)
    x = np.concatenate((plant.GetPositions(plant.CreateDefaultContext()), rng.normal(0, 1, plant.num_velocities())))
    builder = DiagramBuilder()
    system = builder.AddSystem(CorrectedJointTorque(plant, c))
    torque_source = builder.AddSystem(ConstantVectorSource(tau_m))
    state_source = builder.AddSystem(ConstantVectorSource(x))
    builder.Connect(torque_source.get_output_port(), system.GetInputPort("measured_torque"))
    builder.Connect(state_source.get_output_port(), system.GetInputPort("state"))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    out = system.GetOutputPort("joint_torque").Eval(system.GetMyContextFromRoot(context))
    np.testing.assert_allclose(out, c.corrected_torque(tau_m, x[plant.num_positions() + 6 :]))
    assert system.HasDirectFeedthrough(0, 0) and system.HasDirectFeedthrough(1, 0)
    # NaN on a port: a ValueError naming it.
    bare = CorrectedJointTorque(plant, c)
    ctx = bare.CreateDefaultContext()
    bad = tau_m.copy()
    bad[2] = np.nan
    bare.GetInputPort("measured_torque").FixValue(ctx, bad)
    bare.GetInputPort("state").FixValue(ctx, x)
    with pytest.raises(ValueError, match="measured_torque"):
        bare.GetOutputPort("joint_torque").Eval(ctx)
    with pytest.raises(ValueError, match="coulomb"):
        CorrectedJointTorque(plant, _corrections())


# ---------------------------------------------------------------------------------------
# Bad input.
# ---------------------------------------------------------------------------------------


def _small_log(plant, N=50):
    nv, nq = plant.num_velocities(), plant.num_positions()
    q = np.zeros((N, nq))
    q[:, 0] = 1.0
    return CalibrationLog(
        time=np.arange(N) * 0.01,
        q=q,
        v=np.zeros((N, nv)),
        measured_torque=np.zeros((N, nv - 6)),
        known_wrenches=np.zeros((N, 12)),
    )


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("q", lambda log: log.q[:, :-1], "CalibrationLog.q must have shape"),
        ("measured_torque", lambda log: log.measured_torque[:-1], "CalibrationLog.measured_torque must have shape"),
        ("known_wrenches", lambda log: log.known_wrenches[:, :6], "CalibrationLog.known_wrenches must have shape"),
        ("v", lambda log: np.where(np.arange(log.v.shape[1]) == 3, np.nan, log.v), "CalibrationLog.v has NaN"),
        ("time", lambda log: log.time[::-1].copy(), "CalibrationLog.time must be strictly increasing"),
        ("time", lambda log: log.time.reshape(-1, 1), "CalibrationLog.time must be 1-D"),
    ],
)
def test_bad_log_fields_name_the_field(hrp4, field, value, message):
    plant, _ = hrp4
    log = _small_log(plant)
    setattr(log, field, value(log))
    with pytest.raises(ValueError, match=message):
        log.validate(plant, 2)


def test_too_short_log(hrp4):
    plant, _ = hrp4
    with pytest.raises(ValueError, match="too short"):
        _small_log(plant, N=10).validate(plant, 2)


def test_npz_round_trip_and_bad_files(hrp4, tmp_path):
    plant, _ = hrp4
    log = _small_log(plant)
    path = tmp_path / "log.npz"
    log.to_npz(path)
    back = CalibrationLog.from_npz(path).validate(plant, 2)
    np.testing.assert_array_equal(back.q, log.q)
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"\x00\x01 not an npz")
    with pytest.raises(ValueError, match="garbage.npz"):
        CalibrationLog.from_npz(garbage)
    with pytest.raises(ValueError, match="missing.npz"):
        CalibrationLog.from_npz(tmp_path / "missing.npz")
    partial = tmp_path / "partial.npz"
    np.savez(partial, time=log.time, q=log.q)
    with pytest.raises(ValueError, match=r"no array \['v', 'measured_torque', 'known_wrenches'\]"):
        CalibrationLog.from_npz(partial)


def test_identification_refuses_bad_input(hrp4, calibration):
    plant, handles = hrp4
    _, log, _, frames = calibration
    broken = copy.copy(log)
    broken.known_wrenches = log.known_wrenches.copy()
    broken.known_wrenches[100, 4] = np.inf
    with pytest.raises(ValueError, match="known_wrenches"):
        identify_model_corrections(plant, broken, known_wrench_frames=frames)
    with pytest.raises(ValueError, match="known_wrenches must have shape"):
        identify_model_corrections(plant, log, known_wrench_frames=frames[:1])
    with pytest.raises(ValueError, match="cutoff_frequency"):
        identify_model_corrections(
            plant, log, known_wrench_frames=frames, options=IdentificationOptions(cutoff_frequency=500.0)
        )


@pytest.mark.slow
def test_joints_the_log_moves_slowly_get_no_viscous_term(hrp4, calibration):
    """Below ~v_s, F_c tanh(qdot / v_s) + b qdot ~ (F_c / v_s + b) qdot: any split of the
    slope fits, and a wrong b extrapolates badly to faster motions. A joint whose 95th
    percentile speed stays under viscous_min_speed v_s keeps b = 0, and its Coulomb term
    carries the low-speed slope: F_c / v_s ~ the true F_c / v_s + b."""
    plant, _ = hrp4
    _, log, truth, frames = calibration
    speed = np.percentile(np.abs(log.v[:, 6:]), 95, axis=0)
    threshold = float(np.median(speed)) / 0.1  # in units of v_s = 0.1 rad/s: half the joints
    options = IdentificationOptions(
        decimation_period=DECIMATION, torque_std=_torque_std(plant), viscous_min_speed=threshold
    )
    corrections = identify_model_corrections(plant, log, known_wrench_frames=frames, options=options)
    names = [j.name() for j in floating_base_topology(plant).joints]
    slow = speed < threshold * 0.1
    assert sorted(corrections.diagnostics["joints_without_viscous"]) == sorted(np.array(names)[slow].tolist())
    assert np.all(corrections.viscous[slow] == 0.0) and np.all(corrections.viscous[~slow] != 0.0)
    strong = slow & (rated_joint_torques(plant) >= 40.0)
    assert strong.any()
    low_speed_slope = truth["coulomb"][strong] / 0.1 + truth["viscous"][strong]
    np.testing.assert_allclose(corrections.coulomb[strong] / 0.1, low_speed_slope, rtol=0.35)


def test_prior_options_are_checked(hrp4):
    plant, _ = hrp4
    with pytest.raises(ValueError, match="torque_offset_prior_std"):
        IdentificationOptions(torque_offset_prior_std=-1.0).validate()
    with pytest.raises(ValueError, match="coulomb_prior_std"):
        IdentificationOptions(coulomb_prior_std=[1.0, np.nan]).validate()


def test_stance_base_velocity_keeps_the_soles_still(hrp4):
    """A state whose soles are still (v in the null space of both F/T frames' Jacobians):
    from its joint rates alone, stance_base_velocity gives back its base twist, whatever
    base twist the log holds, and reports the frames' speed by the log's own twist."""
    plant, handles = hrp4
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, handles)
    frames = [handles.ft_sensor_frames["left"], handles.ft_sensor_frames["right"]]
    rng = np.random.default_rng(3)
    world = plant.world_frame()
    q = plant.GetPositions(context).copy()
    q[7:] += rng.normal(scale=0.05, size=q.size - 7)
    plant.SetPositions(context, q)
    J = np.vstack(
        [
            plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, f, np.zeros(3), world, world)
            for f in frames
        ]
    )
    null_space = np.linalg.svd(J)[2][np.linalg.matrix_rank(J) :].T
    v = null_space @ rng.normal(size=null_space.shape[1])
    assert np.linalg.norm(v[:6]) > 0.1  # the base moves with the joints
    logged = v.copy()
    logged[:6] += rng.normal(scale=0.05, size=6)  # e.g. a gyro's noise
    states = np.vstack((q, q)), np.vstack((v, logged))
    twist, frame_speed = stance_base_velocity(plant, plant.CreateDefaultContext(), frames, *states)
    np.testing.assert_allclose(twist, np.vstack((v[:6], v[:6])), atol=1e-10)
    assert frame_speed[0] < 1e-10 and frame_speed[1] > 0.01
    with pytest.raises(ValueError, match="at least one frame"):
        stance_base_velocity(plant, context, [], *states)
    with pytest.raises(ValueError, match="base_velocity"):
        IdentificationOptions(base_velocity="imu").validate()


def _measured_part(plant, log, frames, unknown_components):
    """The log with each frame's wrench cut to what its sensor measures: the components
    not in ``unknown_components`` (of [m; f] in the frame's axes, at each sample's q)."""
    context = plant.CreateDefaultContext()
    wrenches = log.known_wrenches.copy()
    for k in range(len(log.time)):
        plant.SetPositions(context, log.q[k])
        for s, frame in enumerate(frames):
            R = frame.CalcPoseInWorld(context).rotation().matrix()
            w = wrenches[k, 6 * s : 6 * s + 6]
            local = np.concatenate((R.T @ w[:3], R.T @ w[3:]))
            local[list(unknown_components)] = 0.0
            wrenches[k, 6 * s : 6 * s + 6] = np.concatenate((R @ local[:3], R @ local[3:]))
    return dataclasses.replace(log, known_wrenches=wrenches)


def test_identification_with_the_feet_shear_and_yaw_unknown(hrp4, calibration):
    """The log of ``test_identification_recovers_known_corrections`` with each foot's
    wrench measured only in part (FSRs: its normal force and the moments about the sole's
    x and y axes; the shear and yaw moment unknown, projected out of every sample's
    equations): the same model, to the same floors."""
    plant, handles = hrp4
    true, log, truth, frames = calibration
    measured = _measured_part(plant, log, frames, SOLE_SHEAR_AND_YAW)
    options = IdentificationOptions(decimation_period=DECIMATION, torque_std=_torque_std(plant))
    corrections = identify_model_corrections(
        plant,
        measured,
        known_wrench_frames=frames,
        options=options,
        unknown_wrench_frames=frames,
        unknown_wrench_components=[SOLE_SHEAR_AND_YAW] * 2,
    )
    weight, com, force_reduction, moment_reduction = _check_gravity(plant, handles, true, corrections, "FSR feet")
    assert abs(weight) < 1e-4
    assert com < 1e-4
    assert force_reduction >= 0.9 and moment_reduction >= 0.9
    rated = rated_joint_torques(plant)
    assert np.max(np.abs(corrections.coulomb / truth["coulomb"] - 1)) < 0.05
    assert np.max(np.abs(corrections.viscous / truth["viscous"] - 1)) < 0.05
    assert np.max(np.abs(corrections.torque_scale - truth["scale"])) < 0.01
    assert np.max(np.abs(corrections.torque_offset - truth["offset"]) / rated) < 0.02
    # Without the projection the unmeasured shear and yaw read as model error: the fit
    # gives joints a torque scale of -100 % or less and is refused.
    with pytest.raises(ValueError, match="does not determine the torque scale"):
        identify_model_corrections(plant, measured, known_wrench_frames=frames, options=options)
