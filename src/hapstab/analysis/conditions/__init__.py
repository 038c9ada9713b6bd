"""The paper's stability conditions, each a sufficient test in the frequency domain: positive-real
(:mod:`~hapstab.analysis.conditions.positive_real`), the circle criterion
(:mod:`~hapstab.analysis.conditions.circle`), sampled-data passivity
(:mod:`~hapstab.analysis.conditions.passivity`), the closed forms
(:mod:`~hapstab.analysis.conditions.closed_forms`) and their audit against the exact limit
(:mod:`~hapstab.analysis.conditions.audit`), on the frequency grids of
:mod:`~hapstab.analysis.conditions.frequency_grid`."""
