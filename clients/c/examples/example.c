/* The weight of a merge at plane 2 on one join path of the model scene, from an artifact. */
#define OPTIMIS_WEIGHTS_IMPLEMENTATION
#include "optimis_weights.h"
#include <stdio.h>

int main(int argc, char **argv) {
    optimis_weights w;
    optimis_path path;
    char err[256];
    const double x2[2] = {0.1, 0.0}, x3[2] = {0.3, 0.05}; /* on planes 2 and 3; the light started at x3 */
    if (argc != 2 || optimis_weights_load_file(argv[1], &w, err, sizeof err) != 0) {
        fprintf(stderr, "%s\n", argc != 2 ? "usage: example ARTIFACT.json" : err);
        return 1;
    }
    optimis_model_path(&w, x2, x3, x3, &path);
    printf("%s: w1 = %.17g\n", w.strategy, optimis_weights_eval(&w, 1, &path));
    optimis_weights_free(&w);
    return 0;
}
