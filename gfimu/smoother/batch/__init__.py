"""The batch engine: a whole log smoothed in overlapping windows, and its Cramér-Rao bound."""
