; Five blocks on the table, stacked cube_a (bottom), cube_b, cube_c, cube_d, cube_e (top), with
; the blocks domain (configs/pddl/tower4_problem.pddl and one block more): a grasp region per
; block, and the place regions that put each block on the one below it (framed by that block).
(define (problem tower5)
  (:domain blocks)
  (:objects
    CubeA_g CubeB_g CubeC_g CubeD_g CubeE_g - grasp_region
    CubeB_on_a CubeC_on_b CubeD_on_c CubeE_on_d - place_region
    cube_a cube_b cube_c cube_d cube_e - block
    table1 - table)
  (:init
    (hand-empty)
    (on cube_a table1) (on cube_b table1) (on cube_c table1) (on cube_d table1) (on cube_e table1)
    (ontable cube_a) (ontable cube_b) (ontable cube_c) (ontable cube_d) (ontable cube_e)
    (clear cube_a) (clear cube_b) (clear cube_c) (clear cube_d) (clear cube_e) (clear table1)
    (is-block cube_a) (is-block cube_b) (is-block cube_c) (is-block cube_d) (is-block cube_e) (is-table table1)
    (grasps CubeA_g cube_a) (grasps CubeB_g cube_b) (grasps CubeC_g cube_c) (grasps CubeD_g cube_d)
    (grasps CubeE_g cube_e)
    (place-on CubeB_on_a cube_b cube_a)
    (place-on CubeC_on_b cube_c cube_b)
    (place-on CubeD_on_c cube_d cube_c)
    (place-on CubeE_on_d cube_e cube_d))
  (:goal (and (on cube_b cube_a) (on cube_c cube_b) (on cube_d cube_c) (on cube_e cube_d) (ontable cube_a))))
