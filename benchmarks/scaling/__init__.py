"""Fig. 3 of the paper: the scaling study over problem and context dimensions (see README.md)."""
