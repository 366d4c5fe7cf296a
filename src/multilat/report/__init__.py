"""Figures and HTML reports. Plot functions take ``ax=None`` and return the axes."""
