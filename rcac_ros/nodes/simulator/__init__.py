"""The simulator node: efforts in, joint states and /clock out (doc/nodes.md)."""
