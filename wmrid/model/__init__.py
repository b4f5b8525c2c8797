"""The robot and its dynamics: the reduced model (Eqs. 9-25), base parameters, robot files, URDF, payload, predictor."""
