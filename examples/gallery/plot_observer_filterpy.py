"""
The hysteresis observer in a filterpy loop
==========================================

x
"""

import matplotlib.pyplot as plt

plt.plot([1, 2])
