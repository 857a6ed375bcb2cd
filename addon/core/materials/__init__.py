"""What surfaces reflect: the Principled BSDF's diffuse energy, its glossy share, textures over patches."""
