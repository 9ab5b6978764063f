"""The learning law as a chain of stages (:mod:`.stage`); importing the package registers every stage kind."""

from . import airframe, band, designed, filters, gain, limit, reference, robust_set  # noqa: F401 - registers the stages
from .stage import CORE_PLACE, apply_learning, STAGE_KINDS, CParts, LawContext, LearningLaw, Stage, register

__all__ = ["apply_learning", "Stage", "CParts", "LawContext", "LearningLaw", "STAGE_KINDS", "CORE_PLACE", "register"]
