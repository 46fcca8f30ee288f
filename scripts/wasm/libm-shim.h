/* Force-included into the C/C++ parts (meshoptimizer, zstd) when building for
 * wasm32-unknown-unknown: the wasm32 stub headers the meshopt crate bundles lack these
 * prototypes; Rust's compiler-builtins supply the functions at link time. */
#ifdef __cplusplus
extern "C" {
#endif
float floorf(float);
float ceilf(float);
float log2f(float);
float frexpf(float, int *);
float ldexpf(float, int);
float cosf(float);
#ifdef __cplusplus
}
#endif
