"""State estimation from the robot's own sensors (IMU, joint encoders, foot contact): the
floating-base state estimator (``base_state_estimator``, the contact-aided invariant EKF of
Hartley et al. 2020) and the contact detection that feeds it; the identification of the
estimators' dynamic model from a calibration log (``model_identification``: link masses and
first moments through the base-parameter regressor, joint friction, motor-torque offset and
scale). Nothing in ``systems.common`` imports this package."""
