"""The probes stage: linear probes, their statistics and controls, fusion, the family protocol.

A family's protocol is spread over one module per concept: `settings` (what config `probes`
says), `rows` (its rows, target and baselines), `fit` (one probe, its regulariser by CV),
`plan` (which comparisons and controls), `compare` (one V vs V+T comparison) and `protocol`
(a whole family, and its tidy tables)."""
