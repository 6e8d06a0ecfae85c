"""core/image.py: the full scale of an image's data."""

import numpy as np

from scipctl.core.image import full_scale


def test_full_scale_of_8_12_and_16_bit_data():
    assert full_scale(np.zeros((2, 2), np.uint8)) == (255.0, 8)
    assert full_scale(np.full((2, 2), 255, np.uint8)) == (255.0, 8)
    assert full_scale(np.array([[0, 4095]], np.uint16)) == (4095.0, 12)  # 12-bit samples in 16-bit words
    assert full_scale(np.array([[0, 4096]], np.uint16)) == (65535.0, 16)
    assert full_scale(np.zeros((0, 0), np.uint16)) == (4095.0, 12)  # nothing above 4095
