"""Detector training sets (``synth trainset render SPEC``): layouts, lightings and views that are never
apt_0..apt_5, and the render job over them.

``trainset``    the trainset spec, preparing its layouts, lightings and views, and rendering them
``appearance``  training layouts' colours and materials redrawn

A single tour (render, check, show, export) is ``synth.tour``.
"""
