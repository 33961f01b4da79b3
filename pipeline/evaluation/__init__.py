"""Evaluation of a perception front end (`r2s eval-frontend`): detection metrics of predicted frames against
ground truth (frontend)."""
