"""Learning-filter design: closed-form filters of the Theorem and their lifted form."""

from .closed_form import LearningFilters, closed_form_filters, simulate_map
from .lifted_filters import LiftedLearningFilters, lifted_filters
from .noncausal import ZPKFilter

__all__ = ["LearningFilters", "closed_form_filters", "simulate_map", "ZPKFilter",
           "LiftedLearningFilters", "lifted_filters"]
