"""The coupled level: the numpy level of the active-set loop (the coupled system and its QP, also the fine
level's reference), its compiled conjugate gradients, and the OSQP backend."""
