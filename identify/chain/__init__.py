"""The measurement chain: from recorded channels to the states q1, q2, q1_dot, its band, its
spectra, its closed-form bias correction, and the same in chunks for records larger than memory."""
