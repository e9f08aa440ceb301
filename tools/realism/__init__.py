"""``rbc realism``: how far the headless simulator's pictures are from the real simulator's, measured.

Image statistics per band of the frame (sky, horizon, far road, near road, bonnet: colour, brightness,
contrast, edge density, sharpness) for a headless recording and a real one side by side, each
difference in units of the real frames' own spread, and a picture: real frames beside their nearest
headless frames, and the statistics' histograms. Every change of the simulator's look is then a number,
not a judgement by eye (issue 23). Imports ``protocol`` and OpenCV; matplotlib only for the picture.
"""
