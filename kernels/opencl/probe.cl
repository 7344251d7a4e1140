/* The smallest kernel: building it tells whether a device's compiler works at all
 * (chronocl.engine.device.build_problem). */
__kernel void probe(__global float *a)
{
    a[get_global_id(0)] += 1.0f;
}
