"""Layer 5 — triangle meshes from lattices (CHoCC paper): CHoCC and ACHoCC hubs, the tessellation
styles, region tessellation, previews, BeCOTS connectors. Computes meshes; never writes files."""
