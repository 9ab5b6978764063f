"""Learning-filter design: closed-form filters of the Theorem and their lifted form."""

from .closed_form import (LearningFilters, closed_form_filters, inverse_gd_filter, reconstruct_disturbance,
                          simulate_map)
from .delta import DeltaSet, delta_set
from .lifted_filters import LiftedLearningFilters, lifted_filters
from .noncausal import ZPKFilter

__all__ = ["LearningFilters", "closed_form_filters", "simulate_map", "ZPKFilter", "inverse_gd_filter",
           "reconstruct_disturbance", "DeltaSet", "delta_set",
           "LiftedLearningFilters", "lifted_filters"]
