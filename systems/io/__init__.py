"""Recorded robot data: ``robot_log`` reads and writes a humanoid's sensor log (CSV, Parquet,
MCAP, ROS 1 bags, ROS 2 bag folders) as one ``RobotLog`` of numpy arrays, the input of the
offline estimators (``diagrams.residuals.log_estimation``)."""
