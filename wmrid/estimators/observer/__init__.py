"""The paper's observer-based estimator (Eqs. 26-37): its readable step and compiled kernel, one pass over a log, the
survey
before it, the replay chunk by chunk and the online form fed as data arrives."""
