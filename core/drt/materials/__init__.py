"""BSDF lobes and the material table."""
