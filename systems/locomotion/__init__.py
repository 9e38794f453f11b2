"""Walking: the ZMP preview-control pattern generator, the Nao walking controller and the
analytic leg inverse kinematics."""
