"""Learning-filter design: closed-form filters of the Theorem and their lifted form, FIR,
norm-optimal and robust designs, model reduction (:mod:`.filters.reduction`), the learning band
that makes every law fly on noisy trials (:mod:`.filters.band`), the acceleration limit
(:mod:`.law.limit`) and the airframe correction for wind on the rigid body (:mod:`.maps.flown`)."""

from .maps.closed_form import (LearningFilters, closed_form_filters, inverse_gd_filter, reconstruct_disturbance,
                               simulate_map)
from .sets.delta import DeltaSet, delta_set
from .filters.band import LearningBand, choose_band
from .law.limit import LearningLimitError, LearningLimitWarning
from .methods.fir import FIRDesign, FIRDesignError, FIRFilter, FIROptions, design_fir
from .methods.norm_optimal import NormOptimalDesigner, NormOptimalOptions, norm_optimal_learning
from .law.laws import LAWS, ExactReference, ReferenceTerms, check_law, law_for, reference_terms
from .methods import FIR, METHODS, ClosedForm, Method, MethodSettings, NormOptimal, Robust, RobustSet
from .pair import LearningSignal, PairDesign, design_pair, with_law
from .methods.robust import RobustDesigner, RobustOptions, RobustPairDesigner
from .checks.theorem import PairCheck, format_theorem_table, theorem_check
from .maps.lifted_filters import LiftedLearningFilters, lifted_filters
from .filters.noncausal import ZPKFilter

__all__ = ["LearningFilters", "closed_form_filters", "simulate_map", "ZPKFilter", "inverse_gd_filter",
           "reconstruct_disturbance", "DeltaSet", "delta_set",
           "FIRDesign", "FIRDesignError", "FIRFilter", "FIROptions", "design_fir",
           "NormOptimalDesigner", "NormOptimalOptions", "norm_optimal_learning",
           "METHODS", "Method", "MethodSettings", "ClosedForm", "FIR", "NormOptimal", "Robust", "RobustSet",
           "ExactReference", "law_for", "PairDesign", "design_pair", "with_law", "LAWS", "check_law", "ReferenceTerms",
           "reference_terms", "PairCheck", "format_theorem_table", "theorem_check",
           "LiftedLearningFilters", "lifted_filters", "RobustDesigner", "RobustOptions", "RobustPairDesigner",
           "LearningBand", "choose_band", "LearningSignal", "LearningLimitError", "LearningLimitWarning"]
