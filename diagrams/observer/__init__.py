"""Hawley et al. (2019) experiments on the simulated Nao: the shared FSR/IMU + observer
pipeline, calibration runs, the standing experiments, walking while pulled, compliant arms and
force-guided walking."""
