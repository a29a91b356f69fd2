// The queue of vertices a centred segment takes again (vertex_queue.h,
// internal): it keeps its vertices in order through any mix of pushes at
// both ends (one or many at a time), drops and growth, and its room stays within a small multiple
// of the most vertices it has held.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <deque>
#include <random>
#include <vector>

#include "vertex_queue.h"

namespace {

using dsm::detail::VertexQueue;

struct Vertex {
    float z;
    double v[3];
    std::uint32_t count;
    double band;
};

template <int C>
Vertex randomVertex(std::mt19937& rng) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    Vertex x{};
    x.z = static_cast<float>(unit(rng) * 100.0);
    for (int c = 0; c < C; ++c) x.v[c] = unit(rng);
    x.count = static_cast<std::uint32_t>(rng() % 1000);
    x.band = (rng() % 4 == 0) ? 0.5 : 0.25;  // runs of one band, as the compressor's
    return x;
}

template <int C>
void expectSame(const VertexQueue& q, const std::deque<Vertex>& model) {
    ASSERT_EQ(q.size(), model.size());
    ASSERT_EQ(q.empty(), model.empty());
    for (std::size_t i = 0; i < model.size(); ++i) {
        ASSERT_EQ(q.depths()[i], model[i].z) << i;
        for (int c = 0; c < C; ++c) ASSERT_EQ(q.values<C>()[i * C + c], model[i].v[c]) << i;
        ASSERT_EQ(q.counts()[i], model[i].count) << i;
        ASSERT_EQ(q.bands()[i], model[i].band) << i;
    }
    if (!model.empty()) {
        std::size_t same = 0;
        while (same < model.size() && same < 8 && model[same].band == model[0].band) ++same;
        EXPECT_EQ(q.sameBand(8), same);
    }
}

template <int C>
void randomOperations(std::uint32_t seed) {
    std::mt19937 rng(seed);
    VertexQueue q;
    std::deque<Vertex> model;
    std::size_t most = 0;
    for (int step = 0; step < 4000; ++step) {
        const std::uint32_t op = rng() % 8;
        if (op < 2) {
            const Vertex x = randomVertex<C>(rng);
            q.pushBack<C>(&x.z, x.v, &x.count, 1, x.band);
            model.push_back(x);
        } else if (op == 2) {
            // A stretch of one band at once, with or without counts.
            const std::size_t n = rng() % 50;
            const bool withCounts = rng() % 2 == 0;
            const double band = randomVertex<C>(rng).band;
            std::vector<float> z(n);
            std::vector<double> v(n * C);
            std::vector<std::uint32_t> counts(n);
            for (std::size_t i = 0; i < n; ++i) {
                Vertex x = randomVertex<C>(rng);
                x.band = band;
                if (!withCounts) x.count = 0;
                z[i] = x.z;
                for (int c = 0; c < C; ++c) v[i * C + c] = x.v[c];
                counts[i] = x.count;
                model.push_back(x);
            }
            q.pushBack<C>(z.data(), v.data(), withCounts ? counts.data() : nullptr, n, band);
        } else if (op < 5) {
            const Vertex x = randomVertex<C>(rng);
            q.pushFront<C>(x.z, x.v, x.count, x.band);
            model.push_front(x);
        } else if (op == 5) {
            // A whole queue ahead of these, as a segment that closes early hands its vertices back.
            VertexQueue other;
            std::deque<Vertex> added;
            const std::size_t n = rng() % 300;
            for (std::size_t i = 0; i < n; ++i) {
                const Vertex x = randomVertex<C>(rng);
                other.pushBack<C>(&x.z, x.v, &x.count, 1, x.band);
                added.push_back(x);
            }
            q.pushFront<C>(other);
            model.insert(model.begin(), added.begin(), added.end());
        } else if (op == 6) {
            const std::size_t n = std::min<std::size_t>(rng() % 40, model.size());
            q.dropFront(n);
            model.erase(model.begin(), model.begin() + static_cast<std::ptrdiff_t>(n));
        } else if (rng() % 16 == 0) {
            q.clear();
            model.clear();
        }
        most = std::max(most, model.size());
        expectSame<C>(q, model);
        if (::testing::Test::HasFatalFailure()) return;
    }
    // Room at both ends grows with what the queue holds, not with how often it grew.
    EXPECT_LE(q.capacity(), 4 * most + 64) << "most held " << most;
}

TEST(VertexQueue, KeepsOrderThroughPushesAtBothEndsOneChannel) {
    for (std::uint32_t seed = 1; seed <= 5; ++seed) randomOperations<1>(seed);
}

TEST(VertexQueue, KeepsOrderThroughPushesAtBothEndsThreeChannels) {
    for (std::uint32_t seed = 11; seed <= 15; ++seed) randomOperations<3>(seed);
}

// The compressor's pattern: a queue drained from the front while vertices,
// one and then many, go back in ahead of it, each time more than before.
TEST(VertexQueue, RoomStaysBoundedWhenTheFrontGrowsAgainAndAgain) {
    VertexQueue q;
    const double v[1] = {0.5};
    std::size_t most = 0;
    for (std::size_t n = 1; n < 6000; n = n * 5 / 4 + 1) {
        q.pushFront<1>(1.0f, v, 1u, 0.25);
        VertexQueue ahead;
        for (std::size_t i = 0; i < n; ++i) {
            const float z = static_cast<float>(i);
            ahead.pushBack<1>(&z, v, nullptr, 1, 0.25);
        }
        q.pushFront<1>(ahead);
        most = std::max(most, q.size());
        ASSERT_EQ(q.size(), n + 1);
        EXPECT_EQ(q.depths()[n - 1], static_cast<float>(n - 1));
        EXPECT_EQ(q.depths()[n], 1.0f);
        q.dropFront(q.size());
    }
    EXPECT_LE(q.capacity(), 4 * most + 64) << "most held " << most;
}

}  // namespace
