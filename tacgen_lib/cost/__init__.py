"""Cost of accuracy: the knob table, each setting's points (metric with its uncertainty
against the seconds of its jobs' benchmark files) and the page's Pareto reading. Run times
themselves are `tacgen_lib.runtime`'s."""
