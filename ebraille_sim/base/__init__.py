"""Foundation layer: compiled-function caching and the shared input-validation vocabulary.

Nothing here knows about the device; every other layer may import it.
"""
