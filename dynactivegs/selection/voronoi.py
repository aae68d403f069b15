"""A Voronoi graph of the known free space, as a networkx graph.

The graph is the medial axis (skeleton, :func:`skimage.morphology.skeletonize`) of the free
cells where the robot's disc fits, i.e. the free space eroded by the robot radius, with
unknown and occupied cells both counted as boundary. It is the roadmap of DESIGN.md §5
Selection: candidate views sit on its nodes, subregions cluster them, the planner runs on it.

Construction (:func:`build_voronoi_graph`):

1. ``traversable = free & clearance >= robot radius`` (clearance as in
   :class:`dynactivegs.sim.freespace.FreeSpace`: distance from a cell centre to the nearest
   non-free cell's boundary; outside the grid counts as non-free).
2. Skeleton pixels, joined 8-connected; a diagonal link is dropped where an orthogonal
   two-step path exists (staircases would otherwise look like junctions).
3. Topological nodes: junction pixels (3 or more links; touching junction pixels form one
   node) and endpoints (1 link). Edges: the pixel chains between them. A closed ring without
   any junction gets a node on its first pixel.
4. Dead ends shorter than ``min_spur_m`` are pruned, shortest first, merging the chains of a
   junction that is left with two edges; a spur whose endpoint is a frontier is kept when
   ``keep_frontier_spurs`` (it leads into unexplored space).
5. Long chains are cut every ~``node_spacing_m`` (chains that would be parallel edges or
   self-loops are always cut so the result is a simple graph).
6. A piece (connected component) of fewer than ``bridge_min_nodes`` nodes is joined to the
   nearest node of a larger piece by an edge along the shortest way through free cells where
   the robot still fits (clearance at least ``bridge_clearance_m``, below the skeleton's),
   at most ``bridge_length_m`` long. A gap a little narrower than the skeleton's clearance cuts
   a robot that squeezed through it off from the rest; this is the way back. It never crosses
   an unknown or occupied cell (an obstacle the camera does not see, once bumped into).

Graph layout:

- nodes: ints ``0..N-1`` in row-major order of their cells; attributes ``xy`` (float64 (2,),
  world metres, the cell centre), ``cell`` ((row, col) ints), ``kind`` (``"junction"``,
  ``"endpoint"``, ``"waypoint"`` or ``"ring"``), ``frontier`` (bool), ``clearance_m`` (float).
- edges: ``length_m`` (polyline length through the cell centres, metres) and ``cells``
  (int64 (k, 2) (row, col) chain from the lower node id to the higher, both ends included;
  consecutive cells are 8-neighbours except within a junction blob, for line integrals);
  a bridge (step 6) has ``bridge`` True.
- ``G.graph``: ``cell_m``, ``origin_xy_m`` (float64 (2,)), ``shape`` ((H, W)).

Grid convention as in :mod:`dynactivegs.selection.occupancy`.
"""

from __future__ import annotations

from dataclasses import dataclass

import networkx as nx
import numpy as np
from scipy import ndimage, sparse
from scipy.spatial import cKDTree
from skimage.graph import MCP_Geometric
from skimage.morphology import skeletonize

from dynactivegs.errors import check_config

_EIGHT = np.ones((3, 3), bool)



@dataclass(frozen=True, slots=True)
class VoronoiConfig:
    """How the Voronoi graph of the known free space is built."""

    robot_radius_m: float = 0.18
    """The robot's radius: the free space is eroded by it plus ``margin_m`` before skeletonizing."""
    margin_m: float = 0.04
    """Clearance kept beyond the robot's radius. Discrete actions cannot steer a disc through a gap a few
    centimetres wider than it (a 10 deg heading error moves a 0.25 m step 4 cm sideways): a robot that squeezed
    through such a door was blocked by its jambs on the way back and stayed in that room."""
    node_spacing_m: float = 0.75
    """Chains longer than this get intermediate nodes about this far apart."""
    min_spur_m: float = 0.5
    """Dead-end branches shorter than this are pruned."""
    keep_frontier_spurs: bool = True
    """Keep short dead ends whose endpoint is a frontier node (they lead into unexplored space)."""
    frontier_dist_m: float = 1.0
    """A node is a frontier node when a frontier cell (unknown, touching known free) is within this distance.
    The skeleton stops about half a passage width short of an open end, so this should exceed that."""
    min_frontier_m: float = 0.3
    """Frontier pieces (8-connected frontier cells) shorter than this (cells x cell size) are ignored: specks of
    unseen floor inside explored space, e.g. between sparse far rays, are not worth a trip."""
    min_component_m: float = 0.25
    """Connected components of the graph whose total edge length is below this are dropped (specks)."""
    bridge_min_nodes: int = 5
    """Pieces of the graph with fewer nodes than this are bridged to a larger piece (construction step 6);
    1: never. Measured: a robot cut off on a piece of two nodes had every view there banned and turned on
    the spot for 75 steps."""
    bridge_length_m: float = 2.0
    """A bridge is at most this long (metres through the grid)."""
    bridge_clearance_m: float = 0.15
    """Clearance every cell of a bridge needs: the robot's 0.18 m radius less the grid's half-cell rounding
    (a gap of 0.40 m, eight 5 cm cells, has a clearance of 0.175 m at its centre cells)."""

    def __post_init__(self) -> None:
        check_config(0.0 <= self.robot_radius_m <= 2.0, "voronoi.robot_radius_m", self.robot_radius_m, "in [0, 2] m")
        check_config(0.0 <= self.margin_m <= 1.0, "voronoi.margin_m", self.margin_m, "in [0, 1] m")
        check_config(self.node_spacing_m > 0.0, "voronoi.node_spacing_m", self.node_spacing_m, "> 0 m")
        check_config(self.min_spur_m >= 0.0, "voronoi.min_spur_m", self.min_spur_m, ">= 0 m")
        check_config(self.frontier_dist_m >= 0.0, "voronoi.frontier_dist_m", self.frontier_dist_m, ">= 0 m")
        check_config(self.min_frontier_m >= 0.0, "voronoi.min_frontier_m", self.min_frontier_m, ">= 0 m")
        check_config(self.min_component_m >= 0.0, "voronoi.min_component_m", self.min_component_m, ">= 0 m")
        check_config(self.bridge_min_nodes >= 1, "voronoi.bridge_min_nodes", self.bridge_min_nodes, ">= 1")
        check_config(self.bridge_length_m >= 0.0, "voronoi.bridge_length_m", self.bridge_length_m, ">= 0 m")
        check_config(self.bridge_clearance_m >= 0.0, "voronoi.bridge_clearance_m", self.bridge_clearance_m, ">= 0 m")


def clearance_m(free: np.ndarray, cell_m: float) -> np.ndarray:
    """float64 (H, W): distance from each free cell's centre to the nearest non-free cell's boundary (0 elsewhere).

    Cells outside the grid count as non-free.
    """
    assert free.ndim == 2 and free.dtype == np.bool_
    padded = np.pad(free, 1, constant_values=False)
    d = ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * cell_m - 0.5 * cell_m
    return np.where(free, np.maximum(d, 0.0), 0.0)


def traversable_mask(free: np.ndarray, cell_m: float, robot_radius_m: float) -> np.ndarray:
    """bool (H, W): free cells where a disc of ``robot_radius_m`` centred on the cell stays in free space."""
    return free & (clearance_m(free, cell_m) >= robot_radius_m)


def frontier_cells(free: np.ndarray, unknown: np.ndarray) -> np.ndarray:
    """bool (H, W): unknown cells 8-adjacent to a free cell. Free cells on the grid's edge make no frontier cell
    inside the grid; :func:`frontier_distance_m` accounts for them."""
    assert free.shape == unknown.shape
    return unknown & ndimage.binary_dilation(free, structure=_EIGHT)


def frontier_distance_m(free: np.ndarray, unknown: np.ndarray, cell_m: float, min_frontier_m: float = 0.0) -> np.ndarray:
    """float64 (H, W): distance from each cell centre to the nearest frontier cell centre (inf if none).

    The ring of cells just outside the grid counts as unknown. Frontier pieces (8-connected)
    with fewer than ``min_frontier_m / cell_m`` cells are ignored.
    """
    f = np.pad(unknown, 1, constant_values=True)
    fr = f & ndimage.binary_dilation(np.pad(free, 1, constant_values=False), structure=_EIGHT)
    if min_frontier_m > 0 and fr.any():
        labels, n = ndimage.label(fr, structure=_EIGHT)
        sizes = np.bincount(labels.ravel(), minlength=n + 1)
        big = sizes * cell_m >= min_frontier_m
        big[0] = False
        fr = big[labels]
    if not fr.any():
        return np.full(free.shape, np.inf)
    return ndimage.distance_transform_edt(~fr)[1:-1, 1:-1] * cell_m


# ---------------------------------------------------------------------- skeleton -> pixel graph
def _pixel_adjacency(skel: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """Skeleton pixels (n, 2) in row-major order and, per pixel, the sorted ids of its linked pixels."""
    h, w = skel.shape
    cells = np.argwhere(skel)
    ids = -np.ones((h + 2, w + 2), np.int64)
    ids[1:-1, 1:-1][skel] = np.arange(len(cells))
    pad = np.pad(skel, 1, constant_values=False)
    rows, cols = [], []
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = ids[1:-1, 1:-1]
        b = ids[1 + di:h + 1 + di, 1 + dj:w + 1 + dj]
        ok = (a >= 0) & (b >= 0)
        if di and dj:   # drop the diagonal where one of the two corner pixels is skeleton too
            ok &= ~pad[1 + di:h + 1 + di, 1:w + 1] & ~pad[1:h + 1, 1 + dj:w + 1 + dj]
        rows += [a[ok], b[ok]]
        cols += [b[ok], a[ok]]
    n = len(cells)
    m = sparse.csr_matrix((np.ones(sum(len(r) for r in rows), np.int8), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n, n))
    m.sort_indices()
    nbrs = [m.indices[m.indptr[k]:m.indptr[k + 1]] for k in range(n)]
    return cells, nbrs


def _chain_length(cells: np.ndarray, cell_m: float) -> np.ndarray:
    """float64 (k,): cumulative polyline length (metres) through the centres of ``cells (k, 2)``."""
    if len(cells) < 2:
        return np.zeros(len(cells))
    step = np.hypot(*np.diff(cells.astype(np.float64), axis=0).T) * cell_m
    return np.concatenate([[0.0], np.cumsum(step)])


@dataclass
class _Topo:
    """Mutable working topology: node key (pixel id) -> kind; edges as [a, b, pixel-id chain a..b]."""

    kind: dict[int, str]
    edges: list[list]

    def degree(self) -> dict[int, int]:
        deg = {k: 0 for k in self.kind}
        for a, b, _ in self.edges:
            deg[a] += 1
            deg[b] += 1
        return deg


def _trace(cells: np.ndarray, nbrs: list[np.ndarray]) -> _Topo:
    n = len(cells)
    deg = np.array([len(x) for x in nbrs], np.int64)
    junction = deg >= 3
    # touching junction pixels form one node; its key is the pixel nearest the blob's mean
    jmask = np.zeros((int(cells[:, 0].max()) + 1 if n else 0, int(cells[:, 1].max()) + 1 if n else 0), bool)
    jmask[cells[junction, 0], cells[junction, 1]] = True
    labels, nlab = ndimage.label(jmask, structure=_EIGHT)
    owner = np.arange(n)                            # pixel id -> node key (only meaningful for node pixels)
    kind: dict[int, str] = {}
    if nlab:
        jl = labels[cells[junction, 0], cells[junction, 1]]
        jid = np.nonzero(junction)[0]
        for lab in range(1, nlab + 1):
            members = jid[jl == lab]
            mean = cells[members].mean(axis=0)
            key = int(members[np.argmin(((cells[members] - mean) ** 2).sum(axis=1))])
            owner[members] = key
            kind[key] = "junction"
    for p in np.nonzero(deg == 1)[0]:
        kind[int(p)] = "endpoint"
    is_node = junction | (deg == 1)
    edges: list[list] = []
    done = np.zeros(n, bool)                        # chain (degree-2) pixels already on an edge
    seen_pairs: set[tuple[int, int]] = set()
    for p in np.nonzero(is_node)[0]:
        for q in nbrs[p]:
            q = int(q)
            if is_node[q] and owner[q] == owner[p]:
                continue
            if (int(p), q) in seen_pairs:
                continue
            chain = [int(p), q]
            prev, cur = int(p), q
            while not is_node[cur]:
                nxt = nbrs[cur][0] if nbrs[cur][0] != prev else nbrs[cur][1]
                prev, cur = cur, int(nxt)
                chain.append(cur)
            seen_pairs.add((cur, prev))
            seen_pairs.add((int(p), q))
            done[chain[1:-1]] = True
            a, b = int(owner[chain[0]]), int(owner[chain[-1]])
            if a != chain[0]:
                chain.insert(0, a)
            if b != chain[-1]:
                chain.append(b)
            edges.append([a, b, chain])
    # rings without any junction: a node on the first pixel, walk around
    for p in np.nonzero(~is_node & (deg == 2) & ~done)[0]:
        if done[p]:
            continue
        kind[int(p)] = "ring"
        chain = [int(p)]
        prev, cur = int(p), int(nbrs[p][0])
        while cur != p:
            chain.append(cur)
            nxt = nbrs[cur][0] if nbrs[cur][0] != prev else nbrs[cur][1]
            prev, cur = cur, int(nxt)
        chain.append(int(p))
        done[chain] = True
        edges.append([int(p), int(p), chain])
    return _Topo(kind, edges)


def _merge_degree_two(topo: _Topo, node: int) -> None:
    """Replace the two edges of a former junction ``node`` by one chain through it."""
    inc = [e for e in topo.edges if node in (e[0], e[1])]
    if len(inc) != 2 or inc[0] is inc[1]:
        return
    e1, e2 = inc
    c1 = e1[2] if e1[1] == node else e1[2][::-1]     # ... -> node
    c2 = e2[2] if e2[0] == node else e2[2][::-1]     # node -> ...
    if c1[0] == node and c2[-1] == node:             # two chains that form a ring through node: keep it
        return
    topo.edges.remove(e1)
    topo.edges.remove(e2)
    topo.edges.append([c1[0], c2[-1], c1 + c2[1:]])
    del topo.kind[node]


def _prune(topo: _Topo, cells: np.ndarray, cell_m: float, cfg: VoronoiConfig, frontier_px: np.ndarray) -> None:
    while True:
        deg = topo.degree()
        best = None
        for e in topo.edges:
            a, b, chain = e
            if a == b:
                continue
            for end, other in ((a, b), (b, a)):
                if deg[end] == 1 and deg[other] >= 3:
                    if cfg.keep_frontier_spurs and frontier_px[end]:
                        continue
                    length = _chain_length(cells[chain], cell_m)[-1]
                    if length < cfg.min_spur_m and (best is None or (length, end) < best[0]):
                        best = ((length, end), e, end, other)
        if best is None:
            return
        _, e, end, other = best
        topo.edges.remove(e)
        del topo.kind[end]
        if deg[other] - 1 == 2:
            _merge_degree_two(topo, other)


def build_voronoi_graph(free: np.ndarray, unknown: np.ndarray, cell_m: float, origin_xy_m: np.ndarray,
                        cfg: VoronoiConfig) -> nx.Graph:
    """The Voronoi graph of the known free space (see the module docstring for layout and steps).

    ``free``, ``unknown``: bool (H, W) cell states (everything else is occupied);
    ``origin_xy_m``: float64 (2,) world xy of cell (0, 0)'s lower-left corner.
    Deterministic: the same inputs give the same node ids, attributes and edge order.
    """
    assert free.ndim == 2 and free.dtype == np.bool_ and unknown.shape == free.shape and unknown.dtype == np.bool_
    origin = np.asarray(origin_xy_m, np.float64)
    assert origin.shape == (2,)
    G = nx.Graph(cell_m=float(cell_m), origin_xy_m=origin.copy(), shape=tuple(free.shape))
    clear = clearance_m(free, cell_m)
    trav = free & (clear >= cfg.robot_radius_m + cfg.margin_m)
    if not trav.any():
        return G
    skel = skeletonize(trav)
    cells, nbrs = _pixel_adjacency(skel)
    if len(cells) == 0:
        return G
    fdist = frontier_distance_m(free, unknown, cell_m, cfg.min_frontier_m)
    frontier_px = fdist[cells[:, 0], cells[:, 1]] <= cfg.frontier_dist_m
    topo = _trace(cells, nbrs)
    # tiny self-loops (a junction blob touching itself through one pixel) are not rings
    topo.edges = [e for e in topo.edges
                  if not (e[0] == e[1] and _chain_length(cells[e[2]], cell_m)[-1] < max(cfg.min_spur_m, 4 * cell_m))]
    for k in [k for k, d in topo.degree().items() if d == 0]:
        del topo.kind[k]
    _prune(topo, cells, cell_m, cfg, frontier_px)

    # subdivide chains into graph edges
    edge_chains: list[tuple[int, int, list[int]]] = []
    kinds = dict(topo.kind)
    used: set[tuple[int, int]] = set()
    for a, b, chain in sorted(topo.edges, key=lambda e: (min(e[0], e[1]), max(e[0], e[1]), e[2])):
        s = _chain_length(cells[chain], cell_m)
        n_seg = max(1, int(round(s[-1] / cfg.node_spacing_m)))
        if a == b:
            n_seg = max(n_seg, 3)
        elif (min(a, b), max(a, b)) in used:
            n_seg = max(n_seg, 2)
        cut = [0]
        for k in range(1, n_seg):
            idx = int(np.argmin(np.abs(s - k * s[-1] / n_seg)))
            if cut[-1] < idx < len(chain) - 1:
                cut.append(idx)
        cut.append(len(chain) - 1)
        if a == b and len(cut) < 4 or (a != b and (min(a, b), max(a, b)) in used and len(cut) < 3):
            continue                                  # too few pixels to make it a simple-graph edge
        for c in cut[1:-1]:
            kinds[chain[c]] = "waypoint"
        for c0, c1 in zip(cut[:-1], cut[1:]):
            u, v = chain[c0], chain[c1]
            used.add((min(u, v), max(u, v)))
            edge_chains.append((u, v, chain[c0:c1 + 1]))

    # drop specks: components whose total length is small
    H = nx.Graph()
    H.add_nodes_from({u for u, _, _ in edge_chains} | {v for _, v, _ in edge_chains})
    lengths = {}
    for u, v, ch in edge_chains:
        lengths[(min(u, v), max(u, v))] = _chain_length(cells[ch], cell_m)[-1]
        H.add_edge(u, v)
    keep: set[int] = set()
    for comp in nx.connected_components(H):
        total = sum(lengths[(min(u, v), max(u, v))] for u, v in H.subgraph(comp).edges)
        if total >= cfg.min_component_m:
            keep |= comp

    order = sorted(keep)                              # pixel ids are row-major, so this is row-major cell order
    nid = {p: i for i, p in enumerate(order)}
    for p in order:
        ij = cells[p]
        G.add_node(nid[p], xy=origin + (ij[::-1].astype(np.float64) + 0.5) * cell_m, cell=(int(ij[0]), int(ij[1])),
                   kind=kinds.get(p, "waypoint"), frontier=bool(frontier_px[p]),
                   clearance_m=float(clear[ij[0], ij[1]]))
    for u, v, ch in sorted(edge_chains, key=lambda e: (nid.get(min(e[0], e[1]), -1), nid.get(max(e[0], e[1]), -1))):
        if u not in nid:
            continue
        ch_cells = cells[ch if nid[u] < nid[v] else ch[::-1]].astype(np.int64)
        ch_cells.flags.writeable = False
        G.add_edge(nid[u], nid[v], length_m=float(_chain_length(ch_cells, cell_m)[-1]), cells=ch_cells)
    for i in G.nodes:
        G.nodes[i]["xy"].flags.writeable = False
    _bridge_pieces(G, clear, cell_m, cfg)
    return G


def _bridge_pieces(G: nx.Graph, clear: np.ndarray, cell_m: float, cfg: VoronoiConfig) -> None:
    """Construction step 6, in place: each piece under ``bridge_min_nodes`` nodes gets at most one bridge, the
    shortest way through cells of clearance >= ``bridge_clearance_m`` to a node of a larger piece (sizes
    before bridging), if it is at most ``bridge_length_m`` long."""
    n = G.number_of_nodes()
    if cfg.bridge_min_nodes <= 1 or n < 2:
        return
    pieces = sorted((sorted(c) for c in nx.connected_components(G)), key=lambda c: c[0])
    label = np.empty(n, np.int64)
    for k, c in enumerate(pieces):
        label[c] = k
    size = np.array([len(c) for c in pieces])
    cell = np.array([G.nodes[i]["cell"] for i in range(n)], np.int64)
    fits = np.where(clear >= cfg.bridge_clearance_m, 1.0, -1.0)        # a negative cost is impassable
    mcp = MCP_Geometric(fits, fully_connected=True)                    # one search per tiny piece below
    for k, comp in enumerate(pieces):
        larger = np.nonzero(size[label] > size[k])[0]
        if size[k] >= cfg.bridge_min_nodes or len(larger) == 0:
            continue
        cum, _ = mcp.find_costs([tuple(cell[a]) for a in comp])
        dist = cum[cell[larger, 0], cell[larger, 1]] * cell_m
        ok = np.isfinite(dist) & (dist <= cfg.bridge_length_m)
        if not ok.any():
            continue
        b = int(larger[ok][np.argmin(dist[ok])])
        chain = np.array(mcp.traceback(tuple(cell[b])), np.int64)
        a = int(comp[int(np.nonzero((cell[comp] == chain[0]).all(axis=1))[0][0])])
        if a > b:
            a, b, chain = b, a, chain[::-1].copy()
        chain.flags.writeable = False
        G.add_edge(a, b, length_m=float(_chain_length(chain, cell_m)[-1]), cells=chain, bridge=True)


def graph_from_occupancy(grid, occ_cfg, cfg: VoronoiConfig) -> nx.Graph:
    """:func:`build_voronoi_graph` of an :class:`~dynactivegs.selection.occupancy.OccupancyGrid`."""
    return build_voronoi_graph(grid.free(occ_cfg), grid.unknown(occ_cfg), grid.cell_m, grid.origin_xy_m, cfg)


def node_xy(G: nx.Graph) -> np.ndarray:
    """float64 (N, 2): node positions in node-id order (node ids are 0..N-1)."""
    if G.number_of_nodes() == 0:
        return np.zeros((0, 2))
    return np.stack([G.nodes[i]["xy"] for i in range(G.number_of_nodes())])


def nearest_node(G: nx.Graph, xy_m: np.ndarray) -> int:
    """Id of the node nearest (straight-line) to ``xy_m (2,)``; -1 for an empty graph.

    Straight-line nearest may lie behind a thin wall; callers that need a reachable node
    should check the segment against their map.
    """
    pts = node_xy(G)
    if len(pts) == 0:
        return -1
    _, i = cKDTree(pts).query(np.asarray(xy_m, np.float64))
    return int(i)


def nearest_clear_node(xy_nodes: np.ndarray, xy_m: np.ndarray, clear: np.ndarray) -> int:
    """Index of the row of ``xy_nodes (N, 2)`` nearest to ``xy_m (2,)`` among those where ``clear (N,)``
    (say, the straight way there is free), the nearest of all when none is; -1 when N is 0."""
    if len(xy_nodes) == 0:
        return -1
    d = np.hypot(xy_nodes[:, 0] - xy_m[0], xy_nodes[:, 1] - xy_m[1])
    return int(np.argmin(np.where(clear, d, np.inf))) if clear.any() else int(np.argmin(d))


@dataclass(frozen=True, slots=True)
class GraphArrays:
    """A graph's edges as arrays, in a fixed order (sorted by ``(u, v)``, ``u < v``)."""

    n_nodes: int
    u: np.ndarray                 # int64 (E,) lower node id
    v: np.ndarray                 # int64 (E,) higher node id
    length_m: np.ndarray          # float64 (E,) polyline length
    cell_start: np.ndarray        # int64 (E + 1,) edge e's cells are cells[cell_start[e]:cell_start[e + 1]]
    cells: np.ndarray             # int64 (C, 2) (row, col) chains from u to v, concatenated

    def __post_init__(self) -> None:
        e = self.u.shape[0]
        assert self.v.shape == (e,) and self.length_m.shape == (e,) and self.cell_start.shape == (e + 1,)
        assert self.cells.ndim == 2 and self.cells.shape[1] == 2 and self.cell_start[-1] == len(self.cells)
        for a in (self.u, self.v, self.length_m, self.cell_start, self.cells):
            a.flags.writeable = False

    @property
    def n_edges(self) -> int:
        return int(self.u.shape[0])


def graph_arrays(G: nx.Graph) -> GraphArrays:
    """The edge arrays of ``G`` (nodes must be ``0..N-1``; edges need ``length_m``, and ``cells`` if line integrals are used)."""
    n = G.number_of_nodes()
    assert set(G.nodes) == set(range(n)), "graph nodes must be 0..N-1"
    edges = sorted((min(a, b), max(a, b)) for a, b in G.edges)
    u = np.array([e[0] for e in edges], np.int64)
    v = np.array([e[1] for e in edges], np.int64)
    length = np.array([G.edges[e]["length_m"] for e in edges], np.float64)
    chains = [np.asarray(G.edges[e].get("cells", np.zeros((0, 2), np.int64)), np.int64).reshape(-1, 2) for e in edges]
    counts = np.array([len(c) for c in chains], np.int64)
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    cells = np.concatenate(chains) if chains else np.zeros((0, 2), np.int64)
    return GraphArrays(n, u, v, length, start, cells)


def edge_list_arrays(n_nodes: int, edges: np.ndarray, length_m: np.ndarray) -> GraphArrays:
    """The edge arrays of a graph given as an edge list (``SelectionOut.edges`` (E, 2) with ``u < v``, sorted,
    and ``edge_length_m`` (E,)), without cell chains: for Dijkstra, not for line integrals."""
    u = edges[:, 0].astype(np.int64)
    v = edges[:, 1].astype(np.int64)
    return GraphArrays(n_nodes, u, v, np.asarray(length_m, np.float64).copy(), np.zeros(len(u) + 1, np.int64),
                       np.zeros((0, 2), np.int64))
