"""The humanoid station shared by every experiment (plant, ground, sensors, PD + gravity
compensation), the plant configuration it accepts (``plant_config``), the ideal and
realistic worlds (``conditions``), the slow whole-body motions of a standing humanoid
(``motions``), and the standing experiment."""
