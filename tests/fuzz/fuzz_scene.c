/*
 * fuzz_scene.c — libFuzzer target: scene text → cs_scene_parse, and for small scenes
 * cs_scene_instantiate and three steps. Nothing may crash, leak or hang; a refusal is fine.
 * Built and run by `make fuzz` (clang; see the Makefile). Seeds: scenes/*.json.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "scene.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size > 4096)
        return 0;
    char *text = malloc(size + 1);
    if (!text)
        return 0;
    memcpy(text, data, size);
    text[size] = '\0';
    if (strstr(text, "\"/")) {
        /* an absolute mesh path: the fuzzer finds assimp's sample models (/usr/share/assimp)
         * among the binary's strings, some of which take seconds to import and voxelize */
        free(text);
        return 0;
    }
    cs_scene sc;
    char err[256];
    if (cs_scene_parse(text, "scenes", &sc, err, sizeof err) == 0) {
        long cells = 0;
        for (int i = 0; i < sc.n_objects; i++)
            cells += sc.objects[i].n_cells;
        cs_world_t *w = NULL;
        /* mesh objects count 0 cells here: they are voxelized by the parse already */
        if (cells < 2000 && cs_scene_instantiate(&sc, &w, err, sizeof err) == 0 && w) {
            for (int k = 0; k < 3; k++)
                cs_world_step(w);
            cs_world_destroy(w);
        }
        cs_scene_free(&sc);
    }
    free(text);
    return 0;
}
