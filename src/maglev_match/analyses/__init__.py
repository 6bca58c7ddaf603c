"""What the user asks for, computed on the maglev models: the matching index,
the critical disturbance, simulations, maps, speed, sensitivities, design and
saved branches."""
