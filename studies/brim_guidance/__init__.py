"""Study: guidance at the stress level brim (its question and commands: README.md)."""
