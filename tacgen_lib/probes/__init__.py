"""The probes stage: linear probes, their statistics and controls, fusion, the family protocol."""
