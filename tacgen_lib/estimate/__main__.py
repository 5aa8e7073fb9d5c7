"""`python -m tacgen_lib.estimate`: the run-time estimate's command (`tacgen_lib.estimate.command`)."""

from tacgen_lib.estimate.command import main

main()
