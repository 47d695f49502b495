//! ODE solvers. (Being written.)
