"""The controller node and its parts: parameters, state and trajectory inputs, outputs,
diagnostics, estimates and their services (doc/nodes.md)."""
