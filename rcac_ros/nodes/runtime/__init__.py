"""What every node process shares: start-up, managed lifecycle, pacing, real-time options,
garbage collector watch, statistics, parameter checks, inputs off the control thread."""
