"""The fail-safe logic: the watchdog, guards of the inputs and of the command (doc/failsafe.md)."""
