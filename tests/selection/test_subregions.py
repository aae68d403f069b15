"""Subregions by eq. (6): distance terms vs. networkx, a busy room splits from its calm neighbour."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from dynactivegs.errors import ConfigError
from dynactivegs.rng import derive_rng
from dynactivegs.selection._reference import dyn_distance_terms_reference
from dynactivegs.selection.subregions import SubregionConfig, cluster_subregions, dyn_distance_terms


def _random_graph(rng: np.random.Generator, n: int) -> nx.Graph:
    pts = rng.uniform(0, 10, size=(n, 2))
    G = nx.Graph()
    for i in range(n):
        G.add_node(i, xy=pts[i])
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    for a in range(n):
        for b in np.argsort(d[a])[1:1 + int(rng.integers(1, 3))]:
            G.add_edge(a, int(b), length_m=float(d[a, b]) * rng.uniform(1.0, 1.3), um_mean=float(rng.uniform(0, 2)))
    return G


def test_distance_terms_equal_the_networkx_reference_on_seeded_random_graphs():
    # Random real lengths make shortest paths unique, so d_M must match to round-off (rtol 1e-12).
    rng = derive_rng(0, "test-subregion-twin")
    for _ in range(8):
        G = _random_graph(rng, int(rng.integers(2, 40)))
        fast = dyn_distance_terms(G)
        ref = dyn_distance_terms_reference(G)
        for f, r in zip(fast, ref):
            np.testing.assert_allclose(f, r, rtol=1e-12, atol=1e-12)
        assert np.isinf(fast[1]).any() or nx.is_connected(G)


def two_rooms(um_busy: float) -> tuple[nx.Graph, np.ndarray, np.ndarray]:
    """Room A (calm) and room B (busy): 3 x 3 nodes 0.75 m apart each, joined by a door node."""
    G = nx.Graph()
    ids = {}
    for room, x0 in (("A", 0.0), ("B", 3.0)):
        for i in range(3):
            for j in range(3):
                ids[(room, i, j)] = len(ids)
                G.add_node(ids[(room, i, j)], xy=np.array([x0 + 0.75 * j, 0.75 * i]))
    door = len(ids)
    G.add_node(door, xy=np.array([2.25, 0.75]))
    for room in "AB":
        um = um_busy if room == "B" else 0.0
        for i in range(3):
            for j in range(3):
                for di, dj in ((0, 1), (1, 0)):
                    if i + di < 3 and j + dj < 3:
                        G.add_edge(ids[(room, i, j)], ids[(room, i + di, j + dj)], length_m=0.75, um_mean=um)
    G.add_edge(ids[("A", 1, 2)], door, length_m=0.75, um_mean=0.0)
    G.add_edge(door, ids[("B", 1, 0)], length_m=0.75, um_mean=um_busy)     # people walk up to the door
    a = np.array([ids[("A", i, j)] for i in range(3) for j in range(3)])
    b = np.array([ids[("B", i, j)] for i in range(3) for j in range(3)])
    return G, a, b


@pytest.mark.parametrize("method", ["average", "complete"])
def test_a_busy_room_splits_from_its_calm_neighbour_and_merges_without_motion_weight(method):
    # Numbers: within a room d_E + d_P <= 2.1 + 3.0 = 5.1; across the rooms d_E + d_P is
    # about 7 on average and at most 4.7 + 6.0 = 10.7 < 12 = cut, so with l_m = 0 all merge.
    # With U_m = 12 in room B (and on the door -> B edge), d_M adds 12 x (metres walked in B),
    # at least 12 x 0.75 = 9 for any A-B pair: even B's doorway node is at d_dyn >= 5 + 9 = 14
    # > 12 from room A on average, so no B node joins A, while A itself (U_m = 0) stays whole.
    G, a, b = two_rooms(um_busy=12.0)
    calm = cluster_subregions(G, SubregionConfig(l_m=0.0, cut_distance=12.0, method=method))
    assert calm.n_regions == 1
    busy = cluster_subregions(G, SubregionConfig(l_m=1.0, cut_distance=12.0, method=method))
    assert busy.n_regions >= 2
    assert len(set(busy.labels[a].tolist())) == 1                        # the calm room is one region
    assert not set(busy.labels[a].tolist()) & set(busy.labels[b].tolist())  # and shares it with no busy node
    assert busy.local_region(int(a[4])) == busy.region_of(int(a[0]))
    assert set(busy.members(busy.local_region(int(a[4]))).tolist()) >= set(a.tolist())
    # the same rooms without people: one region even with the motion weight on
    G0, _, _ = two_rooms(um_busy=0.0)
    assert cluster_subregions(G0, SubregionConfig(l_m=1.0, cut_distance=12.0, method=method)).n_regions == 1


def test_components_never_merge_and_labels_are_deterministic():
    G, a, b = two_rooms(0.0)
    G.remove_node(18)                                                    # the door: two components
    G = nx.relabel_nodes(G, {n: i for i, n in enumerate(sorted(G.nodes))})
    r = cluster_subregions(G, SubregionConfig(l_m=0.0, cut_distance=1e6))
    assert r.n_regions == 2 and r.labels[0] == 0
    r2 = cluster_subregions(G, SubregionConfig(l_m=0.0, cut_distance=1e6))
    np.testing.assert_array_equal(r.labels, r2.labels)
    one = nx.Graph()
    one.add_node(0, xy=np.zeros(2))
    assert cluster_subregions(one, SubregionConfig()).n_regions == 1
    assert cluster_subregions(nx.Graph(), SubregionConfig()).n_regions == 0


def test_config_validation():
    with pytest.raises(ConfigError):
        SubregionConfig(l_m=-1.0)
    with pytest.raises(ConfigError):
        SubregionConfig(method="ward")  # type: ignore[arg-type]
    with pytest.raises(ConfigError):
        SubregionConfig(l_e=0.0, l_p=0.0)
