"""Built-in primitive kinds. Each module is one kind; :mod:`deepmorph_primitives.plugin`
registers them through the ``deepmorph`` entry point, exactly as a third-party plugin would."""
