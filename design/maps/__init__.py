"""Maps of the loops: the Theorem's filters from the loop maps ``Gd``, ``Gf`` and their inverses
(:mod:`.closed_form`), their lifted (whole-trial) operators (:mod:`.finite_horizon`,
:mod:`.lifted_filters`), the disturbance's path through the airframe (:mod:`.flown`) and the
reference error of a loop (:mod:`.reference`). Built on :mod:`..filters`."""
