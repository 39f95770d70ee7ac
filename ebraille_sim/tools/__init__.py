"""Tools layer: sweeps, the regression suite, run reports and test-suite assertions."""
