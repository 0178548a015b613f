"""``homocal ui``: a local browser page over the library (server: homocal.ui.server, page: static/)."""
