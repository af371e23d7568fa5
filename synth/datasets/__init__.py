"""Detector training sets: layouts, lightings and views that are never apt_0..apt_5, and their render job.

``trainset``    ``synth trainset render SPEC``: the detector's training data
``appearance``  training layouts' colours and materials redrawn

A single tour (render, check, show, export) is ``synth.tour``.
"""
