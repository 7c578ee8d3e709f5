"""Controller design: filters, gains, allocation weights, feasible-force polytope."""
