"""The limits of a study: how many designs and parameters it may have, how deep a swept value
may nest, how large a range of whole numbers may be; each checked before any design is
built."""

#: Most designs a study may have: its grid (cases x the product of the lists' lengths) or
#: its ``sample``, counted before any design is built. Every design is checked before the
#: first solve, and the table is rewritten as each design finishes (the cost of both at
#: the limit: docs/sweeps.md, "Limits").
MAX_DESIGNS = 10_000
#: Most parameters a study may vary ([sweep] keys and the cases' keys together).
MAX_PARAMETERS = 100
#: Deepest nesting of a swept value (a domain [[a, b], [c, d]] is 2 deep).
MAX_DEPTH = 8
#: Largest magnitude of a bound of a range of whole numbers (max_iter, multistart, seed):
#: every whole number up to it is a float, and a draw holds it.
MAX_WHOLE = 2 ** 53
#: Largest grid that ``sample = K`` draws its K indices from (NumPy's 64-bit integers); a
#: larger grid of lists is sampled a value of each list at a time.
MAX_INDEX = 2 ** 62
#: Longest label of a swept value in a design's name; a longer one is named by its kind.
MAX_LABEL = 60
