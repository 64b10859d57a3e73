"""Recordings as the rig wrote them: channels, file readers, data quality."""
