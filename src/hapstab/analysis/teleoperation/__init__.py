"""Teleoperation's own questions: is the two-port absolutely stable
(:mod:`~hapstab.analysis.teleoperation.twoport`) and what does the operator feel
(:mod:`~hapstab.analysis.teleoperation.transparency`)."""
