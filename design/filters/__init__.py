"""Filters and their file form, the lowest room of the design (above the kernel only): the non-causal
ZPK filter (:mod:`.noncausal`), its coefficient form in ``filters.json`` (:mod:`.coefficients`,
checked by :mod:`.entries`, written as C text by :mod:`.c_text`), the learning band's low-pass and its
choice (:mod:`.band`), trial-edge continuations (:mod:`.trial_edges`, :mod:`.trial_inverse`), model
reduction (:mod:`.reduction`) and the frequency grids designs optimise over (:mod:`.frequency_grid`)."""
