"""Lights in Cycles's units: sampling, selection, intersection for MIS."""
