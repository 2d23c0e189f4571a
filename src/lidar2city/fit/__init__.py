"""Model fitting: plan and height fitting of parametric primitives (and polygons)."""
