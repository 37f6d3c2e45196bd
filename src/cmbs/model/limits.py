"""The range of the numbers of a model (docs/model-format.md, section 1, "Range of numbers").

Models are in SI units.  The limits are far beyond any mechanism, and keep what the model
computes from the numbers (squares and products in M, K and the energies: at most ~1e48; 1/L
and 1/L²) far from the overflow of double precision (1.8e308), so that a mistaken value is
refused at load, naming its entry, instead of overflowing or dividing by zero in a run.
"""

#: the largest magnitude of a number of a model: coordinate, length, mass, inertia, gravity,
#: stiffness, damping, gain, initial value, table time or value
MAX_MAGNITUDE = 1e12
#: the shortest length of a segment or spring relative to the model size (the largest point
#: coordinate or given length, at least 1 m): still resolved to ~4 digits by coordinates of
#: that size (double precision: 2.2e-16 of them)
MIN_LENGTH_RATIO = 1e-12
