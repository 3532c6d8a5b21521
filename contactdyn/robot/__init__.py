"""The robot: Pinocchio's model of a URDF (by name or path, checked), its frames, its start posture,
and the compiled rigid-body terms (H, h, Jacobians) for trees of revolute and prismatic joints."""
