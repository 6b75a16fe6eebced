"""Characterisation: theory against Monte Carlo, Table 1 end to end, rates, containment, scoring against truth."""
