"""What a user describes: tags, materials, test models, tagged meshes and material fields."""
