"""MCAP: the record reader, topics and joints to a wheel log, the writer."""
