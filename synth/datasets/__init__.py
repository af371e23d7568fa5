"""Tour datasets as a whole: checking rendered tour folders and building detector training sets.

``check``     ``synth dataset check``: every frame, pose and ground-truth file of a tour
``trainset``  the detector's training data (layouts and tours that are never apt_0..apt_5)
"""
