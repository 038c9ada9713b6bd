"""K_max over a box of uncertain operators (:mod:`~hapstab.analysis.robust.robust`, its
result in :mod:`~hapstab.analysis.robust.robust_result`) and the damping that is best for
the whole box (:mod:`~hapstab.analysis.robust.robust_damping`)."""
