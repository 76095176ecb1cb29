/*
 * demo_beam.h — the fracture demo beam's material on a test object (scenes/fracture.json's
 * "brittle": E 2 MPa, ρ 100 kg/m³, damping 0.5 / 0.002, 2.5 cm cubes), for the tests that
 * rebuild its pieces.
 */
#ifndef CS_TEST_DEMO_BEAM_H
#define CS_TEST_DEMO_BEAM_H

#include "cubesim.h"

static inline void demo_beam_material(cs_object_def *d)
{
    d->material.young = 2e6;
    d->material.density = 100;
    d->material.damping[0] = 0.5;
    d->material.damping[1] = 0.002;
    d->cube_size = 0.025;
}

#endif
