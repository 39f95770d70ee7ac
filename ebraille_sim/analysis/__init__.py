"""Analysis layer: linearisation of the loop, frequency analysis, and robust tuning across readers."""
