"""What friction and encoder quantisation do: passivity with both
(:mod:`~hapstab.analysis.nonlinear.nonlinear_passivity`), their describing functions
(:mod:`~hapstab.analysis.nonlinear.harmonic`) and the limit cycles they predict
(:mod:`~hapstab.analysis.nonlinear.limit_cycles`)."""
