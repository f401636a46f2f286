"""Choices made from the data: the model checked against the log (white noise or robust, which
motion model) and the process noise tuned by the evidence of the readings."""
