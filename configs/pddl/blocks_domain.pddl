; Blocks world for an arm at a table: pick a clear block up (from the table or from another
; block) and put it down on the table or on a clear block (stacking).
;
; Each action is one of realize's action templates (grasp, place). Objects of type `region`
; (and its subtypes) are the task's symbolic parameters; the first `block` argument named like a
; scene object (scene.objects) is the object the action handles; every other argument (the
; support it leaves or lands on) is bookkeeping that realize drops when it maps a PDDL action
; to a template call (realize/tasks/pddl.py). A table is a support that is always clear.
(define (domain blocks)
  (:requirements :strips :typing :conditional-effects)
  (:types
    region support - object
    block table - support
    grasp_region place_region - region)
  (:predicates
    (on ?x - block ?s - support)            ; ?x rests on the table or block ?s
    (ontable ?x - block)                     ; ?x rests on a table
    (clear ?s - support)                     ; nothing rests on ?s (a table always is)
    (holding ?x - block)
    (hand-empty)
    (is-block ?s - support)                  ; static: ?s is a block (stacking on it covers it)
    (is-table ?s - support)                  ; static: ?s is a table
    (grasps ?g - grasp_region ?x - block)    ; ?g holds grasp poses of ?x
    (place-on ?r - place_region ?x - block ?s - support))  ; ?r holds poses that put ?x on ?s

  (:action grasp
    :parameters (?g - grasp_region ?x - block ?from - support)
    :precondition (and (hand-empty) (clear ?x) (on ?x ?from) (grasps ?g ?x))
    :effect (and (not (hand-empty)) (holding ?x) (not (on ?x ?from)) (not (ontable ?x)) (clear ?from)))

  (:action place
    :parameters (?r - place_region ?x - block ?s - support)
    :precondition (and (holding ?x) (clear ?s) (place-on ?r ?x ?s))
    :effect (and (not (holding ?x)) (hand-empty) (on ?x ?s)
                 (when (is-block ?s) (not (clear ?s)))
                 (when (is-table ?s) (ontable ?x)))))
