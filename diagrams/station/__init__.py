"""The humanoid station shared by every experiment (plant, ground, sensors, PD + gravity
compensation) and the standing experiment."""
