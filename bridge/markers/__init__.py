"""RViz markers, Paths, polygons and points as Slicer models placed by tf
(`bridge.markers.capability`)."""
