; Three blocks on the table, stacked cube_a (bottom), cube_b, cube_c (top), with the blocks
; domain. Regions are the task's parameters: a grasp region per block, and the place regions
; that put cube_b on cube_a and cube_c on cube_b (framed by the block below).
(define (problem tower3)
  (:domain blocks)
  (:objects
    CubeA_g CubeB_g CubeC_g - grasp_region
    CubeB_on_a CubeC_on_b - place_region
    cube_a cube_b cube_c - block
    table1 - table)
  (:init
    (hand-empty)
    (on cube_a table1) (on cube_b table1) (on cube_c table1)
    (ontable cube_a) (ontable cube_b) (ontable cube_c)
    (clear cube_a) (clear cube_b) (clear cube_c) (clear table1)
    (is-block cube_a) (is-block cube_b) (is-block cube_c) (is-table table1)
    (grasps CubeA_g cube_a) (grasps CubeB_g cube_b) (grasps CubeC_g cube_c)
    (place-on CubeB_on_a cube_b cube_a)
    (place-on CubeC_on_b cube_c cube_b))
  (:goal (and (on cube_b cube_a) (on cube_c cube_b) (ontable cube_a))))
