"""Does the scoop's physics converge? (README.md)"""
