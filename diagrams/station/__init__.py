"""The humanoid station shared by every experiment (plant, ground, sensors, PD + gravity
compensation), the plant configuration it accepts (``plant_config``), and the standing
experiment."""
