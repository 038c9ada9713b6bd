"""The analyses, each a function over the engine's model: exact (certified),
circle criterion, passivity, closed forms, K-B regions, audit. The front door is
:func:`critical_stiffness` and :func:`boundary`."""

from hapstab.analysis.methods import METHODS, boundary, critical_stiffness, methods_for

__all__ = ["critical_stiffness", "boundary", "methods_for", "METHODS"]
