"""Triangle-mesh queries and topology: closest points, rays, distance grids, adjacency, charts."""
