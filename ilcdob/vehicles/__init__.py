"""Vehicle models: the nonlinear 6-DOF quadrotor (:mod:`.quadrotor`) that flies the identification
experiments and the nonlinear validation in place of real vehicles."""
