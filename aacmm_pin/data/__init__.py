"""Files and measurements: the column table, campaign and points readers and writers, the output folder."""
