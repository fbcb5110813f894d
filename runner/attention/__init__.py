"""Attention: the explorer that decides where the hand probes next (pi_per, pi_obj and pi_tar
asked at every step), its cues (saliency, uncertainty, inhibition of return), the shape cue's
matching of templates, and the compiled kernels they share.

It reads a scenario from the world and knows nothing of experiments, reports or robots.
"""
