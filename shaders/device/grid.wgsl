
// Indexing helpers every shader gets, after the contract constants (`gpu::with_contract`).
// The host lays a dispatch's workgroups out in two dimensions when there are more than
// one dimension allows (`Gpu::groups`); these recover the linear indices.

fn workgroup_index(wg: vec3<u32>, groups: vec3<u32>) -> u32 {
    return wg.y * groups.x + wg.x;
}

// The index of an invocation of a one-dimensional kernel of GROUP invocations per
// workgroup.
fn linear_id(wg: vec3<u32>, groups: vec3<u32>, lid: u32) -> u32 {
    return workgroup_index(wg, groups) * GROUP + lid;
}
