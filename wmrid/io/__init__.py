"""Reading and writing logs: format sniffing, CSV, Parquet, signal conversion, inspection."""
