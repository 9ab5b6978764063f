"""What plants may be: the Delta set of a model (:mod:`.delta`), the value sets of structured
uncertainty (:mod:`.value_set`) and the worst-case ratio over them (:mod:`.worst_case`)."""
