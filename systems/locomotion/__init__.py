"""Motion references: the ZMP preview-control pattern generator, the Nao walking controller,
the analytic leg inverse kinematics, posture schedules and the slow sinusoidal whole-body
motions (``posture_motion``)."""
