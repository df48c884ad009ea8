"""Miss / WNN / NN1 (text under Table 8.5), k-NN, confusion matrix, similarity matrix, heat-map."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.classify import (
    confusion_matrix,
    error_stats,
    knn_accuracy,
    knn_predict,
    merge_ties,
    plot_similarity,
    similarity_matrix,
)
from mrfpe.distances import get
from mrfpe.distances.grid import correlation_matrix
from mrfpe.posterior import build

NAN = np.nan


def brute_force(S, classes):
    """Miss, WNN, NN1 with explicit loops, straight from the thesis's wording."""
    n = len(classes)
    miss = wnn = nn1 = 0
    for i in range(n):
        intra = [S[i][j] for j in range(n) if j != i and classes[j] == classes[i]]
        extra = [S[i][j] for j in range(n) if classes[j] != classes[i]]
        worst_intra = min(intra)
        row_miss = sum(1 for s in extra if s > worst_intra)
        miss += row_miss
        wnn += row_miss > 0
        nn1 += bool(extra) and max(extra) > max(intra)
    return {"miss": miss, "wnn": wnn, "nn1": nn1}


# Hand-worked: materials 0-2 in class "a", 3-5 in class "b".
HAND = np.array([
    #  0    1    2    3    4    5
    [NAN, 9.0, 5.0, 6.0, 4.0, 7.0],  # row 0: worst intra 5; extra 6, 7 > 5 -> 2 misses;
    #                                   best intra 9 > best extra 7 -> no NN1 error
    [8.0, NAN, 7.0, 9.0, 1.0, 2.0],  # row 1: worst intra 7; extra 9 > 7 -> 1 miss; 9 > 8 -> NN1
    [5.0, 6.0, NAN, 1.0, 2.0, 3.0],  # row 2: worst intra 5; no extra above -> clean
    [2.0, 3.0, 1.0, NAN, 8.0, 9.0],  # row 3: worst intra 8; clean
    [7.0, 6.0, 5.0, 4.0, NAN, 3.0],  # row 4: worst intra 3; extra 7, 6, 5 > 3 -> 3 misses,
    #                                   best extra 7 > best intra 4 -> NN1
    [1.0, 2.0, 3.0, 4.0, 4.0, NAN],  # row 5: worst intra 4; extra 3 < 4 -> clean
])
HAND_CLASSES = ["a", "a", "a", "b", "b", "b"]


def test_hand_worked_example():
    assert error_stats(HAND, HAND_CLASSES) == {"miss": 6, "wnn": 3, "nn1": 2}
    assert brute_force(HAND, HAND_CLASSES) == {"miss": 6, "wnn": 3, "nn1": 2}


def test_ties_count_as_no_error():
    S = np.array([
        [NAN, 5.0, 5.0, 1.0],  # extra 5 ties the worst (and best) intra 5: no Miss, no NN1
        [5.0, NAN, 2.0, 2.0],
        [1.0, 3.0, NAN, 3.0],  # extra 3 ties best intra 3: no NN1; but 3 > 1? 1 is extra
        [4.0, 4.0, 4.0, NAN],  # all equal: nothing
    ])
    classes = [0, 0, 1, 1]
    # row 0: intra {5}, extra {5, 1} -> nothing.  row 1: intra {5}, extra {2, 2} -> nothing.
    # row 2: intra {3}, extra {1, 3} -> tie, nothing.  row 3: intra {4}, extra {4, 4} -> nothing.
    assert error_stats(S, classes) == {"miss": 0, "wnn": 0, "nn1": 0}
    S[2, 1] = 3.0 + 1e-8  # a hair above the tie is an error
    assert error_stats(S, classes) == {"miss": 1, "wnn": 1, "nn1": 1}
    S[2, 1] = np.nextafter(np.nextafter(3.0, 4.0), 4.0)  # two ulps above: rounding, a tie
    assert error_stats(S, classes) == {"miss": 0, "wnn": 0, "nn1": 0}


def test_ties_are_exact_arithmetic_not_rounding():
    # One-hot weight vectors on a 1000-point grid: the correlation of any two with their
    # weight on different points is -1/999 in exact arithmetic, but the product rounds it
    # a few ulps either way; the statistics and the neighbours must not depend on that.
    n, rng = 1000, np.random.default_rng(3)
    classes = np.repeat(np.arange(4), 3)
    w = np.full((classes.size, n), 1e-300)
    w[np.arange(classes.size), rng.permutation(n)[:classes.size]] = 1.0
    S = correlation_matrix(w)
    off = ~np.eye(classes.size, dtype=bool)
    assert np.ptp(S[off]) < 1e-15
    exact = np.full_like(S, -1.0 / (n - 1))
    for noisy in (S, exact + 1e-18 * rng.standard_normal(S.shape)):
        assert error_stats(noisy, classes) == error_stats(exact, classes) == {
            "miss": 0, "wnn": 0, "nn1": 0}
        assert np.array_equal(knn_predict(noisy, classes), knn_predict(exact, classes))


def test_merge_ties_keeps_real_gaps_and_infinities():
    S = np.array([[9.0, 1.0, -np.inf], [1.0 + 1e-15, 9.0, 2.0], [2.0 + 1e-9, np.inf, 9.0]])
    M = merge_ties(S)
    assert M[1, 0] == 1.0  # 1e-15 relative: the same value as S[0, 1]
    assert M[2, 0] == 2.0 + 1e-9 and M[1, 2] == 2.0  # 5e-10 relative: a real gap
    assert M[0, 2] == -np.inf and M[2, 1] == np.inf and np.all(np.diag(M) == 9.0)


def test_the_diagonal_is_ignored_whatever_it_holds():
    for diag in (NAN, np.inf, -np.inf, 0.0, 1e9):
        S = HAND.copy()
        np.fill_diagonal(S, diag)
        assert error_stats(S, HAND_CLASSES) == {"miss": 6, "wnn": 3, "nn1": 2}


def test_rows_are_the_first_argument_for_asymmetric_matrices():
    S = np.array([[NAN, 1.0, 2.0, 0.0],
                  [1.0, NAN, 0.0, 0.0],
                  [0.0, 0.0, NAN, 5.0],
                  [0.0, 0.0, 5.0, NAN]])
    # only row 0 sees an extra-class entry (2) above its intra-class one (1); in the
    # transpose that 2 sits in row 2, whose intra-class similarity is 5
    assert error_stats(S, [0, 0, 1, 1]) == {"miss": 1, "wnn": 1, "nn1": 1}
    assert error_stats(S.T, [0, 0, 1, 1]) == {"miss": 0, "wnn": 0, "nn1": 0}


def test_thesis_table_8_3_block():
    """Rows/columns 1-16 of Table 8.3 (AGMMP, σ = 0.005), four materials per class.

    The text works row 1: worst intra-class similarity 971.7 (entry (1, 4)); within
    columns 5-16, ten entries exceed it (all but 964.6 and 965.7).
    """
    upper = [
        [993.7, 990.5, 992, 971.7, 975, 985.9, 964.6, 989.1, 988.8, 991.8, 965.7, 985.4,
         985.1, 979, 978.5, 974.5],
        [994.7, 990.4, 968, 972.8, 987.3, 962.9, 988.6, 984.5, 987.9, 964.4, 983.5, 986.3,
         979.3, 979.3, 973.8],
        [993.1, 961.5, 979.7, 986.7, 971.2, 986.4, 984.5, 990.1, 956.1, 987.6, 980.6, 973,
         971.1, 968.5],
        [999.4, 935.5, 968.1, 912.3, 996.2, 995.2, 990.7, 999.4, 961.7, 997.1, 997.7, 997.7,
         997.8],
        [993.2, 974.7, 991, 982, 953.1, 975.7, 882.9, 989.6, 942.6, 930.2, 924.8, 915.6],
        [994.2, 970.5, 983.6, 974.9, 983.9, 932.3, 981.6, 977, 969.5, 966.1, 960],
        [992.6, 975.3, 934, 964.6, 847.3, 983.3, 925.3, 906.9, 902.1, 887.9],
        [994.5, 990.4, 988.9, 985.8, 971, 993, 991, 990.8, 989.4],
        [996.3, 994.6, 990.6, 976.7, 991.8, 989.4, 989.3, 987.8],
        [994.8, 975.4, 984.5, 985.7, 982.2, 982.3, 977.8],
        [999.9, 959.7, 997.3, 998.4, 998.3, 998.5],
        [993.6, 962.4, 954.3, 953.2, 943.5],
        [997.1, 996.1, 996.4, 995.3],
        [998.7, 998.4, 998.5],
        [998.7, 998.4],
        [999.4],
    ]
    S = np.zeros((16, 16))
    for i, row in enumerate(upper):
        S[i, i:] = row
    S = np.triu(S) + np.triu(S, 1).T
    classes = np.repeat(np.arange(4), 4)
    assert int((S[0, 4:] > 971.7).sum()) == 10
    assert error_stats(S, classes) == brute_force(S, classes)
    # row 1's share alone: make every other row error-free
    only_row0 = S.copy()
    only_row0[1:, :] = np.where(classes[1:, None] == classes[None, :], 1000.0, 0.0)
    np.fill_diagonal(only_row0, NAN)
    assert error_stats(only_row0, classes) == {"miss": 10, "wnn": 1, "nn1": 0}


@pytest.mark.parametrize("seed", range(5))
def test_matches_brute_force_on_random_matrices_with_ties(seed):
    rng = np.random.default_rng(seed)
    classes = rng.permutation(np.repeat(np.arange(5), 3))
    S = rng.integers(0, 6, (15, 15)).astype(float)  # small range: many ties
    np.fill_diagonal(S, NAN)
    assert error_stats(S, classes) == brute_force(S, classes)


def test_bad_matrices_raise():
    with pytest.raises(ValueError, match="square"):
        error_stats(np.zeros((3, 4)), [0, 0, 1])
    with pytest.raises(ValueError, match="one label per row"):
        error_stats(np.zeros((4, 4)), [0, 0, 1])
    S = HAND.copy()
    S[0, 3] = NAN
    with pytest.raises(ValueError, match=r"NaN off the diagonal.*\(0, 3\)"):
        error_stats(S, HAND_CLASSES)
    with pytest.raises(ValueError, match=r"at least two members.*'c'"):
        error_stats(np.zeros((3, 3)), ["a", "a", "c"])


# -- k-NN --------------------------------------------------------------------------
def test_loo_1nn_errors_equal_nn1_without_ties():
    rng = np.random.default_rng(7)
    classes = np.repeat(np.arange(6), 4)
    S = rng.random((24, 24)) + 0.4 * (classes[:, None] == classes[None, :])
    np.fill_diagonal(S, NAN)
    pred = knn_predict(S, classes, k=1)
    expect = np.array([classes[np.nanargmax(S[i])] for i in range(24)])  # NaN diagonal
    np.testing.assert_array_equal(pred, expect)
    assert int((pred != classes).sum()) == error_stats(S, classes)["nn1"]
    assert knn_accuracy(S, classes) == pytest.approx(np.mean(pred == classes))


def test_knn_handles_negative_and_infinite_similarities():
    classes = np.array([0, 0, 0, 1, 1, 1])
    S = -np.abs(np.subtract.outer(classes, classes)) * 10.0 - 1.0  # negative everywhere
    S[0, 3] = -np.inf
    np.fill_diagonal(S, NAN)
    assert knn_accuracy(S, classes, k=1) == 1.0
    assert knn_accuracy(S, classes, k=3) == 1.0
    with pytest.raises(ValueError, match="k must be"):
        knn_predict(S, classes, k=6)


def test_confusion_matrix_is_labelled_and_counts_the_predictions():
    classes = np.array(["felt", "felt", "felt", "foil", "foil", "foil"])
    S = np.array([[NAN, 5, 1, 9, 0, 0],  # felt #0 looks most like foil #3
                  [5, NAN, 4, 0, 0, 0],
                  [1, 4, NAN, 0, 0, 0],
                  [0, 0, 0, NAN, 6, 5],
                  [0, 0, 0, 6, NAN, 5],
                  [0, 0, 0, 5, 5, NAN]], dtype=float)
    cm = confusion_matrix(S, classes)
    assert cm.dims == ("true", "predicted")
    assert list(cm["true"].values) == ["felt", "foil"]
    np.testing.assert_array_equal(cm.values, [[2, 1], [0, 3]])
    assert int(cm.sum()) == 6


# -- similarity matrix -----------------------------------------------------------
def sets(n=4, seed=0):
    rng = np.random.default_rng(seed)
    return [build(0.1 * k + 0.2 * rng.standard_normal((20, 2)), np.zeros(20),
                  param_names=["u", "v"], log_weight=rng.standard_normal(20), sampler="test")
            for k in range(n)]


def grid_sets(n=3, seed=0):
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 3)), -1).reshape(-1, 2)
    return [build(g, np.zeros(12), param_names=["u", "v"], log_weight=rng.standard_normal(12),
                  sampler="test") for _ in range(n)]


def test_similarity_matrix_sign_conventions():
    posts = sets()
    kl = get("kl")()
    D = np.array([[kl(a, b) for b in posts] for a in posts])
    np.testing.assert_allclose(similarity_matrix(posts, "kl"), -D, rtol=1e-10, atol=1e-12)
    ag = get("agmmp")()
    L = np.array([[ag.log_similarity(a, b, sigma=0.01) for b in posts] for a in posts])
    np.testing.assert_allclose(similarity_matrix(posts, "agmmp", sigma=0.01), L, rtol=1e-12)
    g = grid_sets()
    corr = get("correlation")()
    R = np.array([[corr.similarity(a, b) for b in g] for a in g])
    np.testing.assert_allclose(similarity_matrix(g, "correlation"), R, rtol=1e-12)


def test_similarity_matrix_parallel_with_progress_equals_serial():
    posts = sets(5)
    serial = similarity_matrix(posts, "emd")
    np.testing.assert_allclose(similarity_matrix(posts, "emd", n_jobs=2, progress=True), serial,
                               rtol=1e-12)
    assert np.all(np.diag(serial) >= -1e-8)  # −EMD(a, a) ≈ 0


def test_similarity_matrix_bad_input():
    with pytest.raises(ValueError, match="at least one"):
        similarity_matrix([], "kl")
    with pytest.raises(ValueError, match="n_jobs"):
        similarity_matrix(sets(2), "kl", n_jobs=0)
    with pytest.raises(ValueError, match="unknown distance"):
        similarity_matrix(sets(2), "nope")
    with pytest.raises(ValueError, match="unknown parameter"):
        similarity_matrix(sets(2), "kl", sigma=1.0)


def test_end_to_end_two_well_separated_classes():
    rng = np.random.default_rng(3)
    posts, classes = [], []
    for c, centre in enumerate(([0.2, 0.2], [0.8, 0.7])):
        for _ in range(3):
            posts.append(build(np.asarray(centre) + 0.05 * rng.standard_normal((30, 2)),
                               np.zeros(30), param_names=["u", "v"],
                               log_weight=rng.standard_normal(30), sampler="test"))
            classes.append(c)
    for name in ("symmetric_kl", "bhattacharyya", "emd", "agmmp", "map_euclidean"):
        S = similarity_matrix(posts, name)
        assert error_stats(S, classes) == {"miss": 0, "wnn": 0, "nn1": 0}, name
        assert knn_accuracy(S, classes) == 1.0


# -- heat-map ------------------------------------------------------------------
def test_plot_outlines_each_class_block():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    classes = ["b", "a", "b", "a", "c", "c"]  # not contiguous: grouped in the picture
    S = np.arange(36.0).reshape(6, 6)
    np.fill_diagonal(S, NAN)
    _, ax = plt.subplots()
    try:
        assert plot_similarity(S, classes, ax=ax, title="test") is ax
        blocks = [p for p in ax.patches if isinstance(p, Rectangle)]
        assert [(b.get_x() + 0.5, b.get_width()) for b in blocks] == [(0, 2), (2, 2), (4, 2)]
        shown = ax.images[0].get_array()
        # grouped order b, b, a, a, c, c = original rows 0, 2, 1, 3, 4, 5
        order = [0, 2, 1, 3, 4, 5]
        np.testing.assert_array_equal(shown.filled(-1), np.nan_to_num(
            S[np.ix_(order, order)], nan=-1))
        assert [t.get_text() for t in ax.get_xticklabels()] == ["1", "3", "2", "4", "5", "6"]
    finally:
        plt.close("all")
    ax2 = plot_similarity(S, classes, colorbar=False)
    assert ax2.images
    plt.close("all")
    with pytest.raises(ValueError, match="one label per row"):
        plot_similarity(S, classes[:3])


def test_bad_arguments_are_named_before_work():
    import numpy as _np
    import pytest as _pytest

    from mrfpe.classify import knn_predict, similarity_matrix

    with _pytest.raises(ValueError, match="S must be a square matrix"):
        knn_predict("abc", [1])
    with _pytest.raises(ValueError, match="name must be a registered distance"):
        similarity_matrix([], 3)
    with _pytest.raises(ValueError, match="posteriors must be a sequence"):
        similarity_matrix("abc", "kl")
    with _pytest.raises(ValueError, match="progress"):
        similarity_matrix([_np.zeros(2)], "kl", progress="yes")
