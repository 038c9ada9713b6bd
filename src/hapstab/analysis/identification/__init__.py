"""A device's mass, damping and Coulomb friction from a recorded log
(:mod:`~hapstab.analysis.identification.identify`)."""
