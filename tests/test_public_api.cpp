// The shape of the public API: versions, the versioned namespace, automatic
// options as unset std::optionals (and given values checked), and no way for a
// caller to reach a class's insides or to make a PixelFunction keep anything
// but a tile alive.
#include <dsm/build.h>
#include <dsm/dsm.h>
#include <dsm/version.h>
#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "temp_dir.h"

namespace {

// Detects a member impl() callable on a (const or not) T.
template <typename T, typename = void>
struct HasImplAccessor : std::false_type {};
template <typename T>
struct HasImplAccessor<T, std::void_t<decltype(std::declval<T&>().impl())>> : std::true_type {};

static_assert(!HasImplAccessor<dsm::DeepShadowMap>::value);
static_assert(!HasImplAccessor<dsm::TileCache>::value);
static_assert(!HasImplAccessor<dsm::SoftShadowTracer>::value);
static_assert(!std::is_constructible_v<dsm::PixelFunction, std::shared_ptr<const void>, dsm::VisibilityView>);
static_assert(std::is_default_constructible_v<dsm::PixelFunction>);

// Every public name is declared in the inline namespace of the major version.
static_assert(std::is_same_v<dsm::VisibilityFunction, dsm::DSM_ABI_NAMESPACE::VisibilityFunction>);
static_assert(std::is_same_v<dsm::DeepShadowMap, dsm::DSM_ABI_NAMESPACE::DeepShadowMap>);
static_assert(std::is_same_v<dsm::Span<const float>, dsm::DSM_ABI_NAMESPACE::Span<const float>>);

// Options whose default means "automatic" say so by being unset.
static_assert(std::is_same_v<decltype(dsm::LookupOptions::level), std::optional<unsigned>>);
static_assert(std::is_same_v<decltype(dsm::SoftShadowOptions::layers), std::optional<int>>);
static_assert(std::is_same_v<decltype(dsm::WriterOptions::mipLevels), std::optional<unsigned>>);
static_assert(std::is_same_v<decltype(dsm::MergeOptions::zlibLevel), std::optional<int>>);
static_assert(std::is_same_v<decltype(dsm::VisibilityProductOptions::maxInterpolationError), std::optional<double>>);
static_assert(std::is_same_v<decltype(dsm::BuildOptions::tolerance), std::optional<double>>);

TEST(PublicApi, LibraryVersionIsTheProjectVersion) {
    EXPECT_STREQ(dsm::libraryVersion(), DSM_PROJECT_VERSION);
    EXPECT_STREQ(DSM_VERSION_STRING, DSM_PROJECT_VERSION);
    const std::string numbers = std::to_string(dsm::kLibraryVersionMajor) + "." +
                                std::to_string(dsm::kLibraryVersionMinor) + "." +
                                std::to_string(dsm::kLibraryVersionPatch);
    EXPECT_EQ(numbers, DSM_PROJECT_VERSION);
}

TEST(PublicApi, WriterWritesTheFormatVersionOfVersionH) {
    dsm::test::TempDir dir;
    const std::string path = (dir / "v.dsm").string();
    dsm::WriterOptions o;
    o.width = 2;
    o.height = 2;
    o.tileSize = 2;
    dsm::MapWriter writer(path, o);
    writer.writeTile(0, 0, std::vector<dsm::VisibilityFunction>(4));
    writer.finish();
    const auto map = dsm::DeepShadowMap::open(path);
    EXPECT_EQ(map->info().versionMajor, dsm::kFormatVersionMajor);
    EXPECT_EQ(map->info().versionMinor, dsm::kFormatVersionMinor);
}

TEST(PublicApi, DefaultPixelFunctionIsEmpty) {
    const dsm::PixelFunction none;
    EXPECT_TRUE(none->empty());
    EXPECT_EQ(none->evaluate(1.0), 1.0);
}

TEST(PublicApi, PixelFunctionKeepsItsTileAfterTheMapCloses) {
    dsm::test::TempDir dir;
    const std::string path = (dir / "p.dsm").string();
    dsm::WriterOptions o;
    o.width = 2;
    o.height = 1;
    o.tileSize = 2;
    std::vector<dsm::VisibilityFunction> pixels(2);
    pixels[1].append(2.0f, 1.0f);
    pixels[1].append(2.0f, 0.25f);
    {
        dsm::MapWriter writer(path, o);
        writer.writeTile(0, 0, pixels);
        writer.finish();
    }
    dsm::ReaderOptions ro;
    ro.cache = dsm::TileCache::create(0);
    dsm::PixelFunction kept;
    {
        const auto map = dsm::DeepShadowMap::open(path, ro);
        kept = map->pixel(0, 1, 0);
    }
    ro.cache->clear();
    ASSERT_EQ(kept->size(), 2u);
    EXPECT_EQ(kept->evaluate(3.0), 0.25);
}

TEST(PublicApi, GivenAutomaticOptionsAreChecked) {
    dsm::test::TempDir dir;
    dsm::WriterOptions o;
    o.width = 2;
    o.height = 2;
    o.mipLevels = 0u;  // unset means a full pyramid; 0 levels means nothing
    EXPECT_THROW(dsm::MapWriter((dir / "m.dsm").string(), o), dsm::Error);
    o.mipLevels = 1u;
    EXPECT_NO_THROW(dsm::MapWriter((dir / "m.dsm").string(), o));

    dsm::VisibilityProductOptions product;
    product.maxInterpolationError = 0.0;
    EXPECT_THROW(dsm::multiplyVisibility({}, product), dsm::Error);
    product.maxInterpolationError = std::numeric_limits<double>::quiet_NaN();
    EXPECT_THROW(dsm::multiplyVisibility({}, product), dsm::Error);
    product.maxInterpolationError = 1e-3;
    EXPECT_NO_THROW(dsm::multiplyVisibility({}, product));
    product.maxInterpolationError.reset();
    EXPECT_NO_THROW(dsm::multiplyVisibility({}, product));
}

}  // namespace
