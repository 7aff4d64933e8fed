"""SVG input and output: secure loading, values, transforms, styles, element reading, writing."""
