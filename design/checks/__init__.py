"""Checks of a design: the Theorem's exact worst case (:mod:`.theorem`) and the design's figures
(:mod:`.figure`)."""
