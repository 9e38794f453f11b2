"""The humanoid station shared by every experiment (plant, ground, sensors, PD + gravity
compensation), the plant configuration it accepts (``plant_config``), its settings and the
ideal and realistic worlds (``config``: ``StationConfig``), the slow whole-body motions of a standing humanoid
(``motions``), and the standing experiment."""
