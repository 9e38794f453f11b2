"""The contact study's random contacts (Flacco et al. 2016, Sec. VI): ``sample_trials`` draws
them on a robot's outer collision surfaces at its standing pose, ``sample_study_trials`` over
the study's seeds; ``body_regions`` names each link's body region (arms, torso, legs).
"""

from collections.abc import Sequence

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex

from diagrams.residuals.contact_study.builder import build_contact_localization_diagram
from diagrams.residuals.contact_study.scenario import (
    MAX_ANGLE_DEG,
    MAX_FORCE,
    MIN_FORCE,
    ContactLocalizationScenario,
    check_force_range,
)
from diagrams.station.config import StationConfig
from systems.residuals.contact_estimation import candidate_geometry
from systems.residuals.geometry_intersection import inward_direction, sample_surface, surface_areas

#: Body regions of the study's per-region table (``body_regions``).
REGIONS = ("arms", "torso", "legs")
_GROUP_REGIONS = {
    "left_arm": "arms",
    "right_arm": "arms",
    "left_hand": "arms",
    "right_hand": "arms",
    "torso": "torso",
    "head": "torso",
    "left_leg": "legs",
    "right_leg": "legs",
}


def body_regions(plant: MultibodyPlant, humanoid) -> dict[str, str]:
    """Body name -> "arms", "torso" or "legs", from the joint group of the first grouped
    joint inboard of the body (``HumanoidHandles.joint_groups``; hands count as arms, the
    head as torso); the base and bodies inboard of every grouped joint are "torso"."""
    group_of = {
        j: _GROUP_REGIONS[g] for g, joints in humanoid.joint_groups.items() if g in _GROUP_REGIONS for j in joints
    }
    inboard = {}
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        inboard[int(joint.child_body().index())] = joint
    regions = {}
    for b in range(plant.num_bodies()):
        body, region = plant.get_body(BodyIndex(b)), "torso"
        joint = inboard.get(b)
        while joint is not None:
            if joint.name() in group_of:
                region = group_of[joint.name()]
                break
            joint = inboard.get(int(joint.parent_body().index()))
        regions[body.name()] = region
    return regions


def sample_trials(
    model: str,
    trials: int,
    seed: int,
    contacts: int = 1,
    force_range: Sequence[float] = (MIN_FORCE, MAX_FORCE),
) -> list[dict]:
    """Random contacts at the standing pose: link uniform over the candidate links, point
    uniform (by area) on the link's collision surface but not inside another link's
    primitive (the outer surface), direction within 60 deg of the inward normal, magnitude
    uniform in ``force_range`` (default [5, 40] N); with ``contacts`` = 2, two such contacts on two different links
    (pushed together). Deterministic from ``seed`` (trial i draws from
    ``default_rng([seed, i])``; a two-contact trial's first contact is the one-contact
    trial's); builds the diagram once, does not simulate.

    Returns one dict per trial: ``trial``, ``noise_seed``, ``contacts`` (one dict per
    contact: ``body``, ``body_index``, ``region`` (``body_regions``), ``geometry``,
    ``point_body`` (m, body frame), ``point_world_nominal`` (m), ``force_world`` (N)), and
    the first contact's fields at the top level.

    Raises:
        ValueError: ``contacts`` other than 1 or 2, or a ``force_range`` that is not
            [min, max] with 0 < min <= max, finite.
    """
    if contacts not in (1, 2):
        raise ValueError(f"contacts must be 1 or 2, got {contacts!r}")
    low, high = check_force_range(force_range)
    _, handles = build_contact_localization_diagram(
        ContactLocalizationScenario(station=StationConfig(model=model, noise=False))
    )
    # The contacts are drawn on the simulated robot's own collision surfaces (the localizer's
    # candidate links: every link but the soles).
    plant = handles.plant
    geo, bodies = candidate_geometry(plant, handles.scene_graph, None, handles.excluded_bodies, "sample_trials")
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, handles.station.initial_state)
    X_WB = np.array([plant.EvalBodyPoseInWorld(context, b).GetAsMatrix34() for b in bodies])
    R_WG, p_WG = geo.world_poses(X_WB)
    areas = surface_areas(geo.kinds, geo.params)
    links = np.unique(geo.body_indices)
    regions = body_regions(plant, handles.station.humanoid)

    def draw(rng: np.random.Generator, other_than: int | None) -> dict:
        for _ in range(1000):
            link = rng.choice(links)
            if link == other_than:
                continue
            rows = np.flatnonzero(geo.body_indices == link)
            g = rng.choice(rows, p=areas[rows] / areas[rows].sum())
            p_G, n_G = sample_surface(geo.kinds[g], geo.params[g], rng)
            p_W = R_WG[g] @ p_G + p_WG[g]
            if geo.outside_other_links(p_W, R_WG, p_WG, link) and p_W[2] > 0.02:  # outer surface, above the ground
                break
        n_W = R_WG[g] @ n_G
        X = X_WB[int(np.searchsorted(geo.bodies, link))]
        force = rng.uniform(low, high) * inward_direction(n_W, rng, MAX_ANGLE_DEG)
        name = plant.get_body(BodyIndex(int(link))).name()
        return {
            "body": name,
            "body_index": int(link),
            "region": regions[name],
            "geometry": geo.names[g],
            "point_body": (X[:, :3].T @ (p_W - X[:, 3])).tolist(),
            "point_world_nominal": p_W.tolist(),
            "force_world": force.tolist(),
        }

    specs = []
    for i in range(trials):
        rng = np.random.default_rng([seed, i])
        drawn = [draw(rng, None)]
        if contacts == 2:
            drawn.append(draw(rng, drawn[0]["body_index"]))
        specs.append({"trial": i, **drawn[0], "contacts": drawn, "noise_seed": (seed * 100003 + i) % (2**31 - 1)})
    return specs


def sample_study_trials(scenario: ContactLocalizationScenario) -> list[dict]:
    """The study's ``trials`` random contacts over its ``num_seeds`` seeds (``sample_trials``
    of seed, seed + 1, ...; the trials split as evenly as they go, the first seeds taking
    the remainder), numbered 0, 1, ... across the seeds; each spec also names its
    ``seed``."""
    specs = []
    per_seed, extra = divmod(scenario.trials, scenario.num_seeds)
    for k in range(scenario.num_seeds):
        count = per_seed + (1 if k < extra else 0)
        seed = scenario.station.seed + k
        trials = (
            sample_trials(scenario.station.model, count, seed, scenario.contacts, scenario.force_range) if count else []
        )
        for spec in trials:
            specs.append({**spec, "trial": len(specs), "seed": seed, "trial_of_seed": spec["trial"]})
    return specs
