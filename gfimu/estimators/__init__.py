"""Per-sample estimators of the papers: a shared base (:mod:`._common`) and one module per method.

The registry of every method by name, smoothers included, is :mod:`gfimu.methods` (the layer
above), which is where ``METHODS``, ``make_estimator``, ``estimator_class``, ``resolve_options`` and
``UnknownMethodError`` live.
"""
