"""Offline closed-loop runs shared by the tools: the loop, the scenarios, the figures of merit
and where the robots' URDFs live."""
