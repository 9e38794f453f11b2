"""What the simulated world adds around the robot: sensors and their noise, scripted pushes
and their ground truth, the pulley load, the PD + gravity-compensation controller and the
Meshcat overlays."""
