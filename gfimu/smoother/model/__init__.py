"""The smoother's model: the state layout, the factor groups with their noise levels, the options
and the smoothing problem they build from a log. Both engines (:mod:`..batch`, :mod:`..stream`)
take every model piece from here."""
