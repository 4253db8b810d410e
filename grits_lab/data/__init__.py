"""Episode datasets on disk: one file per episode plus a Parquet index, readable with numpy and pandas."""
