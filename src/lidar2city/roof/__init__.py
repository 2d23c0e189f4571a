"""LoD2.2 roofs: facet segmentation, 2-D roof topology, adjustment, intersection edges, solids.

The steps of the main seed's framework (Fig. 1, steps 2-8), each a pure function:
:func:`~lidar2city.roof.facets.segment_planes` (facets, eq. 1),
:func:`~lidar2city.roof.topology.roof_partition` (raw 2-D topology and its
simplification), :func:`~lidar2city.roof.refine.refine_partition` (intersection and
step edges, eq. 2) and :func:`~lidar2city.roof.solid.partition_solid` (closed solid).
:func:`~lidar2city.roof.building.reconstruct_lod22` chains them for one building.
"""
