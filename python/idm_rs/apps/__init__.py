"""Applications built on the layers below: the paper case and its figures, the actuator
designer's characteristics (steady state, stall force, velocity/step/back-slip curves) and the
command line (``idm-rs``)."""
