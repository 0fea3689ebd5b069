"""The FollowJointTrajectory action server: goals accepted, tolerances, outcome (doc/nodes.md)."""
