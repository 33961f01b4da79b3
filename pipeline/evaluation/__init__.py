"""Evaluation of a perception front end (`r2s eval-frontend`): detection metrics of predicted frames against
ground truth (frontend)."""

# Matched pairs farther apart than this (metres) are rejected; here (not in frontend.py, which loads numpy) so that
# `r2s eval-frontend --help` shows it without loading the evaluation.
DEFAULT_MAX_DISTANCE = 5.0
