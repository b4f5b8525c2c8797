"""Table logs: CSV (and other delimited text) and Parquet read piece by piece, and the column mapping they share."""
