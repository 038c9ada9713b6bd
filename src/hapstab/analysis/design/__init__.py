"""Design questions over the (K, B) plane: the stability region
(:mod:`~hapstab.analysis.design.regions`, on :mod:`~hapstab.analysis.design.kb_plane`),
the best virtual damping (:mod:`~hapstab.analysis.design.damping`) and the Z-width
(:mod:`~hapstab.analysis.design.zwidth`)."""
