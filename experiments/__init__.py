"""Experiments and the command line (installed as ``drake_abs.experiments``)."""
