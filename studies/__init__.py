"""The studies run with grits_lab, one package a question; the framework never imports them."""
