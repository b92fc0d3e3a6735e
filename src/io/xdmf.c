/* xdmf.c — results.xdmf: the XDMF 3 index of the HDF5 frames (hdf5.c).
 *
 * ParaView, VisIt and meshio read a time series of meshes from one XML file
 * whose arrays stay in the HDF5 files. The index is a Temporal Collection of
 * Uniform grids, one per frame:
 *
 *   <Xdmf Version="3.0"><Domain>
 *     <Grid Name="tissue" GridType="Collection" CollectionType="Temporal">
 *       <Grid Name="frame_NNNNNN" GridType="Uniform">
 *         <Time Value="t"/>                      (%.17g: the frame's time attribute)
 *         <Topology TopologyType="Hexahedron">   results_NNNNNN.h5:/connectivity
 *         <Geometry GeometryType="XYZ">          results_NNNNNN.h5:/points
 *         <Attribute Center="Node">              .../point_data/<name>
 *         <Attribute Center="Cell">              .../cell_data/<name>
 *       </Grid> ...
 *
 * Each frame carries its own topology and geometry, so frames of a refined
 * mesh (other node and cell counts) are ordinary members of the series. A
 * <DataItem> names the frame's own file (results_NNNNNN.h5, relative: the
 * files stay together) even when its connectivity is an external link to an
 * earlier frame's: HDF5 follows the link, the index need not know.
 *
 * Choices:
 * - The <Grid> elements are kept as text and the whole file is rewritten
 *   (nh_write_text: tmp + rename) each time a frame is added, as the PVD
 *   collections are: the file is always complete and lists exactly the
 *   frames of results.h5 (hdf5.c writes it after the frame and results.h5).
 *   About 2 KB per frame.
 * - The attribute type follows the number of components: 1 Scalar, 3
 *   Vector, 6 Tensor6 (Voigt), 9 Tensor, else Matrix. Float64 arrays are
 *   "Float" precision 8, the Int32 point flag "Int" precision 4.
 * - Array names are XML-escaped; hdf5.c refuses names with '/' or ':' (the
 *   HDF5 path and the XDMF "file:path" separators).
 * - The index is built from a frame's layout alone (sizes, names,
 *   components), so the resume (hdf5_resume.c) rebuilds the entries of the
 *   frames it keeps from the stored datasets without reading their data. */
#include "io/io_impl.h"

#include <stdio.h>
#include <stdlib.h>

int nh_xdmf_write(const nh_xdmf *x) {
  nh_text b = {0};
  int rc = nh_text_printf(&b,
                          "<?xml version=\"1.0\" ?>\n"
                          "<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n"
                          "<Xdmf Version=\"3.0\" xmlns:xi=\"http://www.w3.org/2001/XInclude\">\n"
                          "  <Domain>\n"
                          "    <Grid Name=\"tissue\" GridType=\"Collection\" "
                          "CollectionType=\"Temporal\">\n"
                          "%s"
                          "    </Grid>\n"
                          "  </Domain>\n"
                          "</Xdmf>\n",
                          x->grids.s ? x->grids.s : "");
  if (rc == NH_OK) rc = nh_write_text(x->path, b.s);
  free(b.s);
  return rc;
}

static const char *attribute_type(int components) {
  switch (components) {
  case 1:
    return "Scalar";
  case 3:
    return "Vector";
  case 6:
    return "Tensor6";
  case 9:
    return "Tensor";
  default:
    return "Matrix";
  }
}

/* A <DataItem> referencing <file>:/[<group>/]<name>. */
static int xdmf_item(nh_text *b, const char *file, const char *group, const char *name, int n,
                     int components, int is_int) {
  NH_TRY(nh_text_printf(b, "          <DataItem Dimensions=\"%d", n));
  if (components > 1) NH_TRY(nh_text_printf(b, " %d", components));
  NH_TRY(nh_text_printf(b, "\" NumberType=\"%s\" Precision=\"%d\" Format=\"HDF\">%s:/%s%s",
                        is_int ? "Int" : "Float", is_int ? 4 : 8, file, group ? group : "",
                        group ? "/" : ""));
  NH_TRY(nh_text_put_xml(b, name));
  return nh_text_printf(b, "</DataItem>\n");
}

static int xdmf_attribute(nh_text *b, const char *file, const char *group, const char *name,
                          const char *center, int n, int components, int is_int) {
  NH_TRY(nh_text_printf(b, "        <Attribute Name=\""));
  NH_TRY(nh_text_put_xml(b, name));
  NH_TRY(nh_text_printf(b, "\" AttributeType=\"%s\" Center=\"%s\">\n", attribute_type(components),
                        center));
  NH_TRY(xdmf_item(b, file, group, name, n, components, is_int));
  return nh_text_printf(b, "        </Attribute>\n");
}

int nh_xdmf_add_frame(nh_xdmf *x, const char *frame, const char *file, double time,
                      const nh_frame *g) {
  size_t keep = x->grids.len;
  nh_text *b = &x->grids;
  int rc =
      nh_text_printf(b,
                     "      <Grid Name=\"frame_%s\" GridType=\"Uniform\">\n"
                     "        <Time Value=\"%.17g\"/>\n"
                     "        <Topology TopologyType=\"Hexahedron\" NumberOfElements=\"%d\">\n",
                     frame, time, g->n_cells);
  if (rc == NH_OK) rc = xdmf_item(b, file, NULL, "connectivity", g->n_cells, 8, 1);
  if (rc == NH_OK)
    rc = nh_text_printf(b, "        </Topology>\n        <Geometry GeometryType=\"XYZ\">\n");
  if (rc == NH_OK) rc = xdmf_item(b, file, NULL, "points", g->n_points, 3, 0);
  if (rc == NH_OK) rc = nh_text_printf(b, "        </Geometry>\n");
  for (int i = 0; rc == NH_OK && i < g->n_point_fields; ++i)
    rc = xdmf_attribute(b, file, "point_data", g->point_fields[i].name, "Node", g->n_points,
                        g->point_fields[i].components, 0);
  if (rc == NH_OK && g->point_int_flags)
    rc = xdmf_attribute(b, file, "point_data", g->point_flag_name ? g->point_flag_name : "flag",
                        "Node", g->n_points, 1, 1);
  for (int i = 0; rc == NH_OK && i < g->n_cell_fields; ++i)
    rc = xdmf_attribute(b, file, "cell_data", g->cell_fields[i].name, "Cell", g->n_cells,
                        g->cell_fields[i].components, 0);
  if (rc == NH_OK) rc = nh_text_printf(b, "      </Grid>\n");
  if (rc) {
    x->grids.len = keep;
    if (x->grids.s) x->grids.s[keep] = '\0';
  }
  return rc;
}

void nh_xdmf_free(nh_xdmf *x) {
  free(x->path);
  free(x->grids.s);
  *x = (nh_xdmf){0};
}
