"""The plant configuration the stations share (``diagrams.station.humanoid_station`` and
``diagrams.station.standing``): Drake's ``MultibodyPlantConfig`` with a discrete step, point
contact (the feet touch the ground through small spheres) and one of SAP's approximations.
"""

from pydrake.multibody.plant import MultibodyPlantConfig

#: Drake's discrete contact approximations the stations accept (``MultibodyPlantConfig``),
#: all solved by SAP. TAMSI is refused: Drake deprecated it (removal on or after 2026-09-01).
CONTACT_APPROXIMATIONS = ("sap", "similar", "lagged")


def default_plant_config() -> MultibodyPlantConfig:
    """The stations' plant: discrete, 1 ms steps, point contact, Drake's SAP solver."""
    return MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap", contact_model="point")


def check_plant_config(plant_config: MultibodyPlantConfig) -> None:
    """Raises a ValueError that says why unless ``plant_config`` is a discrete plant with
    point contact and one of ``CONTACT_APPROXIMATIONS``."""
    contact_approximation = plant_config.discrete_contact_approximation
    if not plant_config.time_step > 0.0:
        raise ValueError(f"plant_config.time_step must be positive (a discrete plant), got {plant_config.time_step}")
    if plant_config.contact_model != "point":
        raise ValueError(
            f"plant_config.contact_model {plant_config.contact_model!r}: the station uses point contact ('point')"
        )
    if contact_approximation == "tamsi":
        raise ValueError(
            "contact approximation 'tamsi': Drake deprecated the TAMSI solver (removal on or after "
            f"2026-09-01); choose one of {CONTACT_APPROXIMATIONS}"
        )
    if contact_approximation not in CONTACT_APPROXIMATIONS:
        raise ValueError(
            f"unknown contact approximation {contact_approximation!r}; choose one of {CONTACT_APPROXIMATIONS}"
        )


__all__ = ["CONTACT_APPROXIMATIONS", "check_plant_config", "default_plant_config"]
