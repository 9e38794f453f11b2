"""The robot as the estimators know it: a MultibodyPlant of their own, separate from the
simulated robot by construction (issue 31).

On a real robot the estimators have a model (the description's CAD values, or a model
refined from a calibration log) and the robot's sensors; they never have the robot itself.
The simulator mirrors this: ``build_estimator_plant`` parses the robot's description into a
plant that is never simulated (no ground, not in the simulation's diagram), with the
estimators' link inertias (a model mismatch, a refined model) written into the model text so
that they are the plant's *default* parameters: every context an estimator creates from it,
and every value it computes, is the estimators' model. The residuals, force estimation, the
detector, both localizers, the base-state EKF, the PD's gravity compensation and the
admittance are all built from it (``diagrams.station.humanoid_station``); the simulated plant
serves the simulator, the sensors and the ground-truth systems only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.geometry import SceneGraph
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import BodyIndex, Frame, SpatialInertia
from pydrake.systems.framework import DiagramBuilder

from models import (
    MODEL_NAMES,
    HumanoidHandles,
    add_humanoid,
    is_humanoid,
    point_contact_scene_graph_config,
    set_standing_state,
    with_link_inertias,
)
from systems.common.topology import FloatingBaseTopology, floating_base_topology, rigid_link_of_bodies
from systems.residuals.contact_estimation import ALL_WRENCH_COMPONENTS, SOLE_SHEAR_AND_YAW
from systems.residuals.sole_wrenches import SoleWrenchCompensation


@dataclass
class EstimatorPlant:
    """The estimators' plant of one robot (no ground, never simulated).

    Attributes:
        robot: the name, description or model file it was built from.
        plant, scene_graph: its finalized plant and SceneGraph (the collision shapes the
            localizers intersect with the line of action).
        humanoid: its handles (frames, joint groups) for a humanoid; None for a model file.
        topology: its floating-base topology (joints in v[6:] order).
        ft_frames: the foot F/T sensor frames, sides sorted (left, right) as the station's.
        excluded_bodies: the links below the F/T sensors, and the whole feet without them
            (never localized: a push there is part of the ground's wrench).
        unknown_wrench_frames: the sole frames of the feet without F/T sensors, sides
            sorted: the ground's wrench there is an unknown of the estimators
            (``unknown_wrench_frames`` of the detector, force estimator and localizers).
        unknown_wrench_components: per unknown wrench frame, its unknown components
            (``unknown_wrench_components`` of the estimators): all six on a foot with
            ``sensing: none``; the shear and yaw moment (``SOLE_SHEAR_AND_YAW``) on a foot
            with FSRs, whose normal force and centre of pressure are known wrenches.
        fsr_sides, fsr_frames: the feet with FSRs (sides sorted) and their sole frames: the
            frames of the known wrenches ``FsrSoleWrenches`` gives, after the F/T frames.
        standing_state: [q; v] standing (a humanoid) or at the posture held in space (a
            model file): the detector's nominal configuration.
        link_inertias: {link name: M_BBo_B} where this model differs from the description
            (empty: the description's own values).
    """

    robot: str
    plant: MultibodyPlant
    scene_graph: SceneGraph
    humanoid: HumanoidHandles | None
    topology: FloatingBaseTopology
    ft_frames: tuple
    excluded_bodies: tuple[str, ...]
    standing_state: np.ndarray
    link_inertias: dict = field(default_factory=dict)
    unknown_wrench_frames: tuple = ()
    unknown_wrench_components: tuple = ()
    fsr_sides: tuple = ()
    fsr_frames: tuple = ()
    _kinematics: object = field(default=None, init=False, repr=False, compare=False)

    def frame_rotations(self, frames: Sequence[Frame], q: np.ndarray) -> np.ndarray:
        """(N, k, 3, 3) R_WF of each of the plant's ``frames`` at each of the positions q
        (N, nq): Pinocchio's forward kinematics on a model built from the plant once
        (``PinocchioFloatingBaseDynamics``, used here for kinematics only), a third of the
        cost of Drake's ``SetPositions`` and ``CalcPoseInWorld`` per sample."""
        if self._kinematics is None:
            from systems.dynamics.pinocchio_dynamics import PinocchioFloatingBaseDynamics  # (imports Pinocchio)

            self._kinematics = PinocchioFloatingBaseDynamics(self.plant)
        return self._kinematics.frame_rotations_of_samples(np.asarray(q, dtype=float), frames)

    @property
    def known_wrench_frames(self) -> tuple:
        """The frames of the measured wrenches eq. (10) subtracts: the F/T sensors' frames,
        then the soles with FSRs (their normal force and centre of pressure)."""
        return tuple(self.ft_frames) + tuple(self.fsr_frames)

    @property
    def contact_candidate_bodies(self) -> tuple:
        """The bodies a push may be on: every body with mass but the world and
        ``excluded_bodies`` (``SoleWrenchCompensation``'s candidates)."""
        excluded = set(self.excluded_bodies)
        bodies = (self.plant.get_body(BodyIndex(i)) for i in range(1, self.plant.num_bodies()))
        return tuple(b for b in bodies if b.name() not in excluded and b.default_mass() > 0.0)

    def sole_wrench_compensation(
        self, gain: float, period: float, residual: str = "internal"
    ) -> SoleWrenchCompensation:
        """The ``SoleWrenchCompensation`` of this robot's soles (its unknown wrench frames and
        components; the push's candidate links ``contact_candidate_bodies``) on residuals of
        gain ``gain`` (1/s) updated every ``period`` s, compensating the ``residual`` one.

        Raises:
            ValueError: no unknown wrench frames (a robot with foot F/T sensors), bad settings.
        """
        return SoleWrenchCompensation(
            self.plant,
            self.unknown_wrench_frames,
            self.unknown_wrench_components,
            gain=gain,
            residual=residual,
            candidate_bodies=self.contact_candidate_bodies,
            period=period,
        )

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The 1-DoF joints in the plant's v[6:] order."""
        return tuple(j.name() for j in self.topology.joints)

    def link_inertias_by_name(self, inertias: Mapping[int, SpatialInertia]) -> dict[str, SpatialInertia]:
        """{body index: M} of this plant's bodies -> {link name: M}."""
        return {self.plant.get_body(BodyIndex(int(i))).name(): M for i, M in inertias.items()}


def build_estimator_plant(
    robot: str,
    time_step: float = 1e-3,
    *,
    link_inertias: Mapping[str, SpatialInertia] | None = None,
) -> EstimatorPlant:
    """The estimators' plant of ``robot``: a built-in name (``hrp4_like``), a robot
    description (``models.add_humanoid``), or a floating-base SDFormat/URDF file (a robot
    floating in zero gravity, as the station simulates it).

    Args:
        time_step: the plant's discrete step, s (only its kind matters to the estimators).
        link_inertias: {link name: M_BBo_B} replacing the description's inertias of those
            links (``models.with_link_inertias``): the plant's default parameters.

    Raises:
        ValueError: an unknown or unreadable model, a model without a floating base, a link
            the model does not have.
    """
    link_inertias = dict(link_inertias or {})
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=time_step), point_contact_scene_graph_config(), builder
    )
    humanoid = None
    if is_humanoid(robot):
        humanoid = add_humanoid(plant, robot, scene_graph=scene_graph, link_inertias=link_inertias)
    else:
        add_model_file(plant, robot, link_inertias)
    plant.Finalize()
    topology = floating_base_topology(plant)  # clear ValueError for a model without a floating base
    context = plant.CreateDefaultContext()
    ft_frames, excluded, unknown, components, fsr_sides = (), (), (), (), ()
    if humanoid is not None:
        set_standing_state(plant, context, humanoid)
        sides = sorted(humanoid.ft_sensor_joints)
        ft_frames = tuple(humanoid.ft_sensor_frames[s] for s in sides)
        excluded = tuple(humanoid.ft_sensor_joints[s].child_body().name() for s in sides)
        unknown_sides = [s for s in sorted(humanoid.sole_frames) if s not in sides]
        unknown = tuple(humanoid.sole_frames[s] for s in unknown_sides)
        fsr_sides = tuple(s for s in unknown_sides if humanoid.foot_sensing.get(s) == "fsr")
        components = tuple(SOLE_SHEAR_AND_YAW if s in fsr_sides else ALL_WRENCH_COMPONENTS for s in unknown_sides)
        link_of = rigid_link_of_bodies(plant)
        for frame in unknown:
            foot = link_of[int(frame.body().index())]
            excluded += tuple(
                plant.get_body(BodyIndex(b)).name()
                for b in range(plant.num_bodies())
                if link_of[b] == foot and plant.get_body(BodyIndex(b)).name() not in excluded
            )
    else:
        set_posture_inside_limits(plant, context, topology)
    return EstimatorPlant(
        robot=str(robot),
        plant=plant,
        scene_graph=scene_graph,
        humanoid=humanoid,
        topology=topology,
        ft_frames=ft_frames,
        excluded_bodies=excluded,
        standing_state=plant.GetPositionsAndVelocities(context),
        link_inertias=link_inertias,
        unknown_wrench_frames=unknown,
        unknown_wrench_components=components,
        fsr_sides=fsr_sides,
        fsr_frames=tuple(humanoid.sole_frames[s] for s in fsr_sides),
    )


def add_model_file(
    plant: MultibodyPlant, model: str, link_inertias: Mapping[str, SpatialInertia] | None = None
) -> None:
    """Parses a floating-base model file (not a humanoid) into ``plant``, gravity off (it
    floats in space, as the station simulates it); the simulated and the estimators' plants
    of such a robot are both parsed here.

    Raises:
        ValueError: a missing or unparsable file, naming it.
    """
    path = Path(model)
    if not path.is_file():
        raise ValueError(
            f"--model: '{model}' is neither one of {MODEL_NAMES}, nor a robot description (.yaml), nor a "
            "readable model file"
        )
    kind = path.suffix.lower().lstrip(".")
    try:
        parser = Parser(plant)
        if link_inertias:
            parser.AddModelsFromString(with_link_inertias(path.read_text(), kind, link_inertias, str(path)), kind)
        else:
            parser.AddModels(str(path))
    except ValueError:
        raise
    except Exception as error:  # Drake's parser raises RuntimeError with its own message
        raise ValueError(f"could not parse the model file '{path}': {error}") from error
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])


def set_posture_inside_limits(plant: MultibodyPlant, context, topology: FloatingBaseTopology) -> None:
    """Default joint positions, moved to the middle of the range where 0 is within 0.05 of a
    joint limit (a limit's constraint force would be an unmodelled external effort)."""
    for joint in topology.joints:
        lower, upper = joint.position_lower_limits()[0], joint.position_upper_limits()[0]
        value = plant.GetPositions(context)[joint.position_start()]
        if not (lower + 0.05 <= value <= upper - 0.05):
            middle = 0.5 * (lower + upper) if np.isfinite(lower) and np.isfinite(upper) else value
            q = plant.GetPositions(context)
            q[joint.position_start()] = middle
            plant.SetPositions(context, q)


__all__ = ["EstimatorPlant", "add_model_file", "build_estimator_plant", "set_posture_inside_limits"]
