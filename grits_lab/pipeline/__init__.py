"""The one-command pipeline: collect -> train -> evaluate -> sweep -> report, resumable stage by stage."""
