"""The classical rivals on the inverse model's regression: IDIM (its rows from zero-phase filtered signals, its checks),
IDIM-IV, RLS (and its compiled kernel), and the low-pass filtering they share."""
